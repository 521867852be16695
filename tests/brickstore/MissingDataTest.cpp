// tests/TestSupport.h's missingData, which every test needing ../shared/data calls when a scan
// is absent: a skip on a developer's machine, a failure under CI=true (where the scans must be).
// Lives with the brickstore tests, the executable every build has.
#include "tests/TestSupport.h"

#include <gtest/gtest-spi.h>

#include <cstdlib>
#include <optional>
#include <vector>

namespace bc::test {
namespace {

/// Sets (or, with nullptr, removes) CI for its lifetime, then puts back what was there.
class ScopedCi {
  public:
    explicit ScopedCi(const char* value) {
        if (const char* old = std::getenv("CI")) mOld = old;
        if (value)
            ::setenv("CI", value, 1);
        else
            ::unsetenv("CI");
    }
    ~ScopedCi() {
        if (mOld)
            ::setenv("CI", mOld->c_str(), 1);
        else
            ::unsetenv("CI");
    }
    ScopedCi(const ScopedCi&) = delete;
    ScopedCi& operator=(const ScopedCi&) = delete;

  private:
    std::optional<std::string> mOld;
};

/// What missingData(what) reports, intercepted instead of reaching this test.
std::vector<::testing::TestPartResult> reportOf(const std::string& what) {
    ::testing::TestPartResultArray results;
    {
        ::testing::ScopedFakeTestPartResultReporter reporter(
            ::testing::ScopedFakeTestPartResultReporter::INTERCEPT_ONLY_CURRENT_THREAD, &results);
        missingData(what);
    }
    std::vector<::testing::TestPartResult> out;
    for (int i = 0; i < results.size(); ++i)
        out.push_back(results.GetTestPartResult(i));
    return out;
}

TEST(MissingData, FailsTheTestNamingTheScanUnderCiTrue) {
    for (const char* value : {"true", "1"}) {
        ScopedCi ci(value);
        EXPECT_TRUE(dataRequired()) << "CI=" << value;
        const auto results = reportOf("scan cthead");
        ASSERT_EQ(results.size(), 1u) << "CI=" << value;
        EXPECT_TRUE(results[0].failed()) << "CI=" << value;
        const std::string message = results[0].message();
        EXPECT_NE(message.find("missing scan cthead"), std::string::npos) << message;
        EXPECT_NE(message.find("CI=true"), std::string::npos) << message;
    }
}

TEST(MissingData, SkipsTheTestWithoutCi) {
    for (const char* value : {static_cast<const char*>(nullptr), "", "false"}) {
        ScopedCi ci(value);
        EXPECT_FALSE(dataRequired()) << "CI=" << (value ? value : "(unset)");
        const auto results = reportOf("scan cthead");
        ASSERT_EQ(results.size(), 1u);
        EXPECT_TRUE(results[0].skipped())
            << "CI=" << (value ? value : "(unset)") << ": " << results[0].message();
    }
}

} // namespace
} // namespace bc::test
