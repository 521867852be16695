#pragma once
// Shared helpers of the test suites: where the real scans are, scratch folders.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

namespace bc::test {

/// Path of a file in ../shared/data (read, never copied).
/// How much slower than a plain build this one runs (BC_TEST_TIME_SCALE, set by
/// scripts/sanitize.sh: ThreadSanitizer runs the CPU renderers 5-15x slower); tests that bound
/// a wait or a gap scale the bound, never drop it.
inline double timeScale() {
    const char* s = std::getenv("BC_TEST_TIME_SCALE");
    const double v = s ? std::atof(s) : 1.0;
    return v >= 1.0 ? v : 1.0;
}

inline std::string dataPath(const std::string& name) {
    std::filesystem::path p = std::filesystem::path(BC_SHARED_DATA_DIR) / name;
    return p.string();
}
inline bool haveData(const std::string& name) {
    return std::filesystem::exists(dataPath(name));
}

/// Whether the real scans must be there: CI=true (or 1) in the environment. CI provides
/// ../shared/data, so a scan missing there is a broken set-up, not a reason to skip.
inline bool dataRequired() {
    const char* ci = std::getenv("CI");
    const std::string v = ci ? ci : "";
    return v == "true" || v == "TRUE" || v == "True" || v == "1";
}

/// Reports `what` (a scan or file of ../shared/data) missing: a failure when dataRequired(), a
/// skip otherwise. The test stops here: `if (!spec) return test::missingData("scan cthead");`.
inline void missingData(const std::string& what) {
    if (dataRequired()) {
        ADD_FAILURE() << "missing " << what << " in " << BC_SHARED_DATA_DIR
                      << " (CI=true: the real scans are required)";
        return;
    }
    GTEST_SKIP() << "missing " << what << " in " << BC_SHARED_DATA_DIR;
}

/// A fresh scratch folder removed with everything in it when the object goes.
class TempDir {
  public:
    TempDir() {
        std::random_device rd;
        mPath = std::filesystem::temp_directory_path() /
                ("bctest-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
        std::filesystem::create_directories(mPath);
    }
    ~TempDir() {
        std::error_code ec;
        std::filesystem::remove_all(mPath, ec);
    }
    TempDir(const TempDir&) = delete;
    TempDir& operator=(const TempDir&) = delete;
    std::string file(const std::string& name) const { return (mPath / name).string(); }
    const std::filesystem::path& path() const { return mPath; }

  private:
    std::filesystem::path mPath;
};

inline void writeFile(const std::string& path, const void* data, std::size_t bytes) {
    std::ofstream f(path, std::ios::binary);
    f.write(static_cast<const char*>(data), static_cast<std::streamsize>(bytes));
}
inline void writeFile(const std::string& path, const std::string& text) {
    writeFile(path, text.data(), text.size());
}
inline std::vector<std::uint8_t> readFile(const std::string& path) {
    std::ifstream f(path, std::ios::binary);
    return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(f), {});
}

/// Fills `folder` with links to `files` (files of the real scans) but for the one named
/// `damaged`, which is written from `bytes` (`data()` and `size()`): a damaged copy of that file
/// among the real others, e.g. one bad slice in a DICOM series. Returns the damaged file's path.
template <typename Bytes>
std::string linkWithDamagedFile(const std::filesystem::path& folder,
                                const std::vector<std::filesystem::path>& files,
                                const std::string& damaged, const Bytes& bytes) {
    std::filesystem::create_directories(folder);
    for (const auto& file : files)
        if (file.filename() != damaged)
            std::filesystem::create_symlink(file, folder / file.filename());
    const std::string path = (folder / damaged).string();
    writeFile(path, bytes.data(), bytes.size());
    return path;
}

/// What a command printed (stdout and stderr together) and its exit status (-1 when it did
/// not exit normally).
struct CommandOutput {
    int exitCode = -1;
    std::string text;
};

/// Runs `commandLine` through the shell with stderr joined to stdout.
inline CommandOutput runCommand(const std::string& commandLine) {
    CommandOutput out;
    FILE* p = ::popen((commandLine + " 2>&1").c_str(), "r");
    if (!p) return out;
    char buf[4096];
    for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, p)) > 0;)
        out.text.append(buf, n);
    const int status = ::pclose(p);
    out.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return out;
}

} // namespace bc::test
