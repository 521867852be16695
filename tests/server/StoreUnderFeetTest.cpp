// A store that changes under a running daemon (truncated, or overwritten in place by `cp`)
// fails that volume only: its client gets an Error naming the store, the volume is taken out
// of service (its other sessions are told, later requests are refused at once, ListVolumes
// leaves it out, /metrics counts it, one log line), the daemon lives on and the client of
// another volume keeps receiving frames; a reload reopens it once the store is valid again and
// its sessions move to it. A store rewritten while every brick its view needs is cached is
// noticed too, without a frame asking. And the start is strict: a configured store that is
// missing, corrupt or not a file (a FIFO) stops the daemon at once, naming it, unless it is
// optional.
#include "ServerTestSupport.h"

#include "server/Catalog.h"
#include "server/Error.h"

#include <fcntl.h>
#include <filesystem>
#include <future>
#include <sys/stat.h>
#include <variant>

namespace bc::server::test {
namespace {

/// A synthetic store of edge^3 voxels in 32^3 bricks (many bricks, spread over the file).
std::string makeStore(const TempDir& dir, const std::string& name, std::uint64_t edge,
                      brickstore::SynthKind kind = brickstore::SynthKind::Phantom) {
    const std::string path = dir.file(name);
    auto source = brickstore::makeSynthetic(kind, {edge, edge, edge}, 1);
    brickstore::IngestConfig config;
    config.geometry = {32, 2, 8};
    brickstore::ingest(*source, path, config);
    return path;
}

DaemonConfig twoStores(const std::string& a, const std::string& b) {
    DaemonConfig c;
    c.source = "<test>";
    c.metricsHost = "127.0.0.1";
    c.metricsPort = 0;
    // Far below one frame's bricks: every frame reads its bricks from the store files again.
    c.hostBudgetBytes = 1ull << 20;
    for (const auto& [name, path] : {std::pair{"first", a}, std::pair{"second", b}}) {
        CatalogEntry e;
        e.name = name;
        e.store = path;
        c.volumes.push_back(e);
    }
    return c;
}

/// One frame at azimuth `az`, or the Error the server sent instead.
std::variant<client::ReceivedFrame, client::ServerError>
frameOrError(client::Client& c, const protocol::VolumeInfo& v, double az, std::uint32_t id) {
    c.setCamera(orbitCamera(v, az, id));
    c.requestFrame();
    try {
        return c.nextFrame();
    } catch (const client::ServerError& e) {
        return e;
    }
}

/// The next Error this client is sent (frames and others skipped) and its request id.
std::pair<protocol::Error, std::uint32_t> nextError(client::Client& c) {
    for (;;) {
        std::uint32_t request = 0;
        auto m = c.nextMessage(&request);
        if (auto* e = std::get_if<protocol::Error>(&m)) return {*e, request};
    }
}

double failedVolumes(const TestDaemon& daemon) {
    return sampleOf(scrape(daemon.daemon->metricsPort(), "GET /metrics HTTP/1.1\r\n\r\n"),
                    "brickcast_volumes_failed");
}

std::size_t count(const std::string& text, const std::string& what) {
    std::size_t n = 0;
    for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1))
        ++n;
    return n;
}

/// Changes the first store with `change` while both volumes are viewed; the first client must
/// get RenderFailed naming the store, the second keeps its frames; the first volume is then out
/// of service: a bystander session on it is told, later frames and OpenVolume are refused at
/// once, ListVolumes and /metrics show it, and the log says so once.
void expectOnlyTheFirstVolumeFails(const std::function<void(const std::string&)>& change,
                                   const std::string& expectWhy) {
    TempDir dir;
    const std::string a = makeStore(dir, "first.bcs", 96), b = makeStore(dir, "second.bcs", 64);
    ::testing::internal::CaptureStderr();
    {
        TestDaemon daemon(twoStores(a, b));
        client::Client first(daemon.clientConfig()), second(daemon.clientConfig());
        client::Client bystander(daemon.clientConfig());
        const auto va = first.openVolume("first"), vb = second.openVolume("second");
        bystander.openVolume("first");
        auto options = smallCpuFrames(48);
        options.level = 0; // full resolution: more bricks than the host budget holds
        first.setRenderOptions(options);
        second.setRenderOptions(options);
        ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(frameOrError(first, va, 0, 1)));
        ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(frameOrError(second, vb, 0, 1)));
        EXPECT_EQ(failedVolumes(daemon), 0.0);

        change(a);

        std::optional<client::ServerError> error;
        std::uint32_t i = 2;
        for (; i < 12 && !error; ++i) {
            auto r = frameOrError(first, va, 30.0 * i, i);
            if (auto* e = std::get_if<client::ServerError>(&r)) error = *e;
        }
        ASSERT_TRUE(error) << "the first client kept getting frames from a changed store";
        EXPECT_EQ(error->code(), protocol::ErrorCode::RenderFailed);
        EXPECT_FALSE(error->fatal());
        EXPECT_NE(std::string(error->what()).find(a), std::string::npos)
            << "the error does not name the store: " << error->what();
        EXPECT_NE(std::string(error->what()).find(expectWhy), std::string::npos) << error->what();
        for (std::uint32_t k = 2; k < 6; ++k) {
            auto r = frameOrError(second, vb, 30.0 * k, k);
            ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(r))
                << "the other volume's client lost its frames: "
                << std::get<client::ServerError>(r).what();
        }

        // The bystander, which asked for nothing, is told unasked (request id 0).
        const auto [told, toldRequest] = nextError(bystander);
        EXPECT_EQ(told.code, protocol::ErrorCode::RenderFailed);
        EXPECT_EQ(toldRequest, 0u);
        EXPECT_NE(told.message.find("volume 'first' is out of service"), std::string::npos)
            << told.message;
        EXPECT_NE(told.message.find(a), std::string::npos) << told.message;
        // Every later frame of it is refused at once, naming why, the store left alone.
        std::size_t refused = 0;
        for (std::uint32_t k = 0; k < 5; ++k, ++i) {
            auto r = frameOrError(first, va, 30.0 * i, i);
            auto* e = std::get_if<client::ServerError>(&r);
            ASSERT_TRUE(e) << "a frame of the failed volume was drawn";
            if (e->code() == protocol::ErrorCode::RenderFailed &&
                std::string(e->what()).find("volume 'first' is out of service") !=
                    std::string::npos)
                ++refused;
        }
        EXPECT_GE(refused, 4u) << "later frames were not refused as out of service";
        // A new client: ListVolumes leaves it out, OpenVolume is refused naming why.
        client::Client third(daemon.clientConfig());
        const auto listed = third.listVolumes();
        ASSERT_EQ(listed.size(), 1u);
        EXPECT_EQ(listed[0].name, "second");
        try {
            third.openVolume("first");
            ADD_FAILURE() << "a failed volume was opened";
        } catch (const client::ServerError& e) {
            EXPECT_EQ(e.code(), protocol::ErrorCode::UnknownVolume);
            EXPECT_NE(std::string(e.what()).find("out of service"), std::string::npos) << e.what();
        }
        EXPECT_EQ(failedVolumes(daemon), 1.0);
    }
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(count(log, "catalog: volume 'first' is out of service"), 1u) << log;
}

TEST(StoreUnderFeet, TruncatedStoreFailsItsVolumeOnlyAndTheDaemonKeepsServing) {
    expectOnlyTheFirstVolumeFails(
        [](const std::string& store) { std::filesystem::resize_file(store, 8192); },
        "changed on disk since it was opened: size");
}

TEST(StoreUnderFeet, StoreOverwrittenByCpFailsItsVolumeOnlyAndTheDaemonKeepsServing) {
    TempDir other;
    const std::string replacement =
        makeStore(other, "replacement.bcs", 48, brickstore::SynthKind::Vessels);
    expectOnlyTheFirstVolumeFails(
        [&](const std::string& store) {
            const auto r = bc::test::runCommand("cp " + replacement + " " + store);
            ASSERT_EQ(r.exitCode, 0) << r.text;
        },
        "changed on disk since it was opened");
}

TEST(StoreUnderFeet, AReloadReopensAFailedVolumeOnceItsStoreIsValidAndItsSessionsMoveToIt) {
    TempDir dir;
    const std::string a = makeStore(dir, "first.bcs", 96), b = makeStore(dir, "second.bcs", 64);
    const std::string file = dir.file("brickcastd.toml");
    bc::test::writeFile(file, "[budgets]\nhost_mb = 1\n[[volume]]\nname = \"first\"\nstore = \"" +
                                  a + "\"\n[[volume]]\nname = \"second\"\nstore = \"" + b + "\"\n");
    DaemonConfig config = DaemonConfig::load(file);
    config.metricsHost = "127.0.0.1";
    config.metricsPort = 0;
    ::testing::internal::CaptureStderr();
    {
        TestDaemon daemon(config);
        client::Client first(daemon.clientConfig());
        const auto va = first.openVolume("first");
        auto options = smallCpuFrames(48);
        options.level = 0;
        first.setRenderOptions(options);
        ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(frameOrError(first, va, 0, 1)));
        std::filesystem::resize_file(a, 8192);
        bool failed = false;
        for (std::uint32_t i = 2; i < 12 && !failed; ++i)
            failed =
                std::holds_alternative<client::ServerError>(frameOrError(first, va, 30.0 * i, i));
        ASSERT_TRUE(failed);
        ASSERT_EQ(failedVolumes(daemon), 1.0);

        makeStore(dir, "first.bcs", 96); // a valid store again (renamed into place)
        daemon.daemon->reload();
        // The session is moved to the reopened volume unasked; Errors before the move are the
        // out-of-service notices.
        std::optional<protocol::VolumeInfo> moved;
        while (!moved) {
            std::uint32_t request = 99;
            auto m = first.nextMessage(&request);
            if (auto* e = std::get_if<protocol::Error>(&m)) {
                ASSERT_EQ(e->code, protocol::ErrorCode::RenderFailed) << e->message;
                continue;
            }
            if (auto* o = std::get_if<protocol::VolumeOpened>(&m)) {
                EXPECT_EQ(request, 0u);
                moved = o->info;
            }
        }
        EXPECT_EQ(moved->dims, va.dims);
        for (std::uint32_t i = 20; i < 23; ++i) {
            auto r = frameOrError(first, va, 30.0 * i, i);
            ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(r))
                << "no frames after the reload: " << std::get<client::ServerError>(r).what();
        }
        client::Client other(daemon.clientConfig());
        EXPECT_EQ(other.listVolumes().size(), 2u);
        EXPECT_EQ(other.openVolume("first").dims, va.dims);
        EXPECT_EQ(failedVolumes(daemon), 0.0);
    }
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(count(log, "catalog: volume 'first' is out of service"), 1u) << log;
}

TEST(StrictStart, AMissingOrCorruptStoreStopsTheStartNamingIt) {
    TempDir dir;
    const std::string good = makeStore(dir, "good.bcs", 32);
    const std::string corrupt = dir.file("corrupt.bcs");
    auto bytes = bc::test::readFile(good);
    bytes[100] ^= 0xff; // inside the header: its checksum fails
    bc::test::writeFile(corrupt, bytes.data(), bytes.size());
    for (const std::string& bad : {dir.file("missing.bcs"), corrupt}) {
        DaemonConfig c = twoStores(good, bad);
        Log quiet(true);
        try {
            Catalog catalog(c, quiet);
            ADD_FAILURE() << "started with " << bad;
        } catch (const ConfigError& e) {
            EXPECT_NE(std::string(e.what()).find("'second'"), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
        }
        EXPECT_THROW(TestDaemon{c}, ConfigError);
    }
}

TEST(StrictStart, AnOptionalMissingStoreIsLeftOutAndACorruptOneStillStops) {
    TempDir dir;
    const std::string good = makeStore(dir, "good.bcs", 32);
    bc::test::writeFile(dir.file("cfg.toml"),
                        "[[volume]]\nname = \"first\"\nstore = \"good.bcs\"\n"
                        "[[volume]]\nname = \"second\"\nstore = \"gone.bcs\"\n"
                        "optional = true\n");
    const DaemonConfig c = DaemonConfig::load(dir.file("cfg.toml"));
    ASSERT_EQ(c.volumes.size(), 2u);
    EXPECT_TRUE(c.volumes[1].optional);
    Log quiet(true);
    Catalog catalog(c, quiet);
    EXPECT_EQ(catalog.size(), 1u);
    EXPECT_FALSE(catalog.lease("second"));
    // Optional covers a missing store only: one that exists and is not a store still stops.
    bc::test::writeFile(dir.file("gone.bcs"), "not a store");
    EXPECT_THROW(Catalog(c, quiet), ConfigError);
    // optional is a store's key only.
    EXPECT_THROW(DaemonConfig::parse("[[volume]]\nname = \"g\"\ngenerate = \"phantom\"\n"
                                     "dims = [8, 8, 8]\noptional = true\n",
                                     "<t>", dir.path().string()),
                 ConfigError);
}

TEST(StrictStart, AStoreThatIsAFifoStopsTheStartAtOnceNamingIt) {
    TempDir dir;
    const std::string good = makeStore(dir, "good.bcs", 32);
    const std::string fifo = dir.file("fifo.bcs");
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    auto start = std::async(std::launch::async, [&]() -> std::string {
        try {
            TestDaemon d(twoStores(good, fifo));
            return "started";
        } catch (const ConfigError& e) {
            return e.what();
        }
    });
    if (start.wait_for(std::chrono::seconds(5)) != std::future_status::ready) {
        // Unblock an open() that waits for a writer, so that the test ends.
        const int writer = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
        start.wait();
        if (writer >= 0) ::close(writer);
        FAIL() << "the start waited on a FIFO for over 5 s";
    }
    const std::string why = start.get();
    EXPECT_NE(why.find(fifo), std::string::npos) << why;
    EXPECT_NE(why.find("not a regular file"), std::string::npos) << why;
}

TEST(StoreUnderFeet, AStoreRewrittenWhileItsBricksAreCachedIsNoticedWithoutAFrame) {
    TempDir dir, other;
    const std::string a = makeStore(dir, "first.bcs", 48), b = makeStore(dir, "second.bcs", 32);
    const std::string replacement =
        makeStore(other, "replacement.bcs", 48, brickstore::SynthKind::Vessels);
    DaemonConfig config = twoStores(a, b);
    config.hostBudgetBytes = 256ull << 20; // every brick stays cached
    TestDaemon daemon(config);
    auto cc = daemon.clientConfig();
    cc.timeoutMs = 10000;
    client::Client c(cc);
    const auto v = c.openVolume("first");
    c.setRenderOptions(smallCpuFrames(48));
    ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(frameOrError(c, v, 0, 1)));
    ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(frameOrError(c, v, 0, 2)));
    const auto r = bc::test::runCommand("cp " + replacement + " " + a);
    ASSERT_EQ(r.exitCode, 0) << r.text;
    // Asked for nothing: told unasked (request id 0), within a few seconds.
    std::uint32_t request = 1;
    const auto m = c.nextMessage(&request);
    ASSERT_TRUE(std::holds_alternative<protocol::Error>(m));
    const auto& e = std::get<protocol::Error>(m);
    EXPECT_EQ(e.code, protocol::ErrorCode::RenderFailed);
    EXPECT_EQ(request, 0u);
    EXPECT_NE(e.message.find(a), std::string::npos) << e.message;
    auto again = frameOrError(c, v, 0, 3);
    ASSERT_TRUE(std::holds_alternative<client::ServerError>(again))
        << "a frame of the old bricks was sent after the store changed";
}

} // namespace
} // namespace bc::server::test
