// SIGHUP reloads the catalog of a running daemon: the config file is read again, volumes are
// added, removed and reopened (their store file changed), one log line each; a session on an
// unchanged volume keeps its frames, one on a removed volume or one reopened with another
// shape gets an Error, one on a volume reopened with the same name, voxel type, dims and
// spacing moves to the new store unasked; a config that fails to parse keeps the old catalog.
// The config and the stores are read off the network thread: clients are served while a file
// takes long to open. The daemon no longer dies of SIGHUP.
#include "ServerTestSupport.h"

#include <csignal>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <set>
#include <sys/stat.h>

namespace bc::server::test {
namespace {

void makeStore(const std::string& path, std::uint64_t edge,
               brickstore::SynthKind kind = brickstore::SynthKind::Phantom) {
    auto source = brickstore::makeSynthetic(kind, {edge, edge, edge}, 1);
    brickstore::IngestConfig config;
    config.geometry = {32, 2, 8};
    brickstore::ingest(*source, path, config); // renamed into place: a new file
}

std::string volumeToml(const std::string& name) {
    return "[[volume]]\nname = \"" + name + "\"\nstore = \"" + name + ".bcs\"\n";
}

void writeConfig(const std::string& path, const std::vector<std::string>& names) {
    std::string text = "[server]\nlisten = \"127.0.0.1:0\"\n";
    for (const auto& n : names)
        text += volumeToml(n);
    std::ofstream(path) << text;
}

std::set<std::string> served(std::uint16_t port) {
    client::ClientConfig cc;
    cc.port = port;
    client::Client c(cc);
    std::set<std::string> names;
    for (const auto& v : c.listVolumes())
        names.insert(v.name);
    return names;
}

/// Polls ListVolumes until it is `want` (a reload runs on the daemon's own thread).
bool waitForCatalog(std::uint16_t port, const std::set<std::string>& want) {
    for (int i = 0; i < 100; ++i) {
        if (served(port) == want) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return false;
}

bool frameArrives(client::Client& c, const protocol::VolumeInfo& v, std::uint32_t id) {
    c.setCamera(orbitCamera(v, 20.0 * id, id));
    c.requestFrame();
    return c.nextFrame().header.cameraId == id;
}

/// The next Error the server sends this client (frames and others skipped).
protocol::Error nextError(client::Client& c) {
    for (;;) {
        auto m = c.nextMessage();
        if (auto* e = std::get_if<protocol::Error>(&m)) return *e;
    }
}

TEST(CatalogReload, SighupReloadsTheCatalogAndLeavesSessionsOnUnchangedVolumesAlone) {
    TempDir dir;
    for (const auto* n : {"keep", "drop", "swap", "added"})
        makeStore(dir.file(std::string(n) + ".bcs"), 32);
    const std::string config = dir.file("brickcastd.toml");
    writeConfig(config, {"keep", "drop", "swap"});
    ::testing::internal::CaptureStderr();
    std::string logText;
    {
        Log log(false);
        Daemon daemon(DaemonConfig::load(config), log, /*handleSignals=*/true);
        std::thread thread([&] { daemon.run(); });
        client::ClientConfig cc;
        cc.port = daemon.port();
        cc.timeoutMs = 20000;
        client::Client keep(cc), drop(cc), swap(cc);
        const auto vk = keep.openVolume("keep");
        const auto vd = drop.openVolume("drop");
        swap.openVolume("swap");
        for (auto* c : {&keep, &drop, &swap})
            c->setRenderOptions(smallCpuFrames(32));
        ASSERT_TRUE(frameArrives(keep, vk, 1));
        ASSERT_TRUE(frameArrives(drop, vd, 1));

        makeStore(dir.file("swap.bcs"), 48); // a new store under the same name
        writeConfig(config, {"keep", "swap", "added"});
        ASSERT_EQ(::kill(::getpid(), SIGHUP), 0);
        EXPECT_TRUE(waitForCatalog(cc.port, {"keep", "swap", "added"}))
            << "ListVolumes did not follow the new config";

        for (std::uint32_t i = 2; i < 5; ++i)
            EXPECT_TRUE(frameArrives(keep, vk, i)) << "the unchanged volume's session broke";
        const auto dropped = nextError(drop);
        EXPECT_EQ(dropped.code, protocol::ErrorCode::UnknownVolume);
        EXPECT_NE(dropped.message.find("'drop'"), std::string::npos) << dropped.message;
        const auto swapped = nextError(swap);
        EXPECT_EQ(swapped.code, protocol::ErrorCode::UnknownVolume);
        EXPECT_EQ(swap.openVolume("swap").dims[0], 48u) << "the reopened volume is the old store";

        // A config that does not parse: logged, the catalog kept, the daemon still serving.
        std::ofstream(config) << "[[volume]\nname = ";
        ASSERT_EQ(::kill(::getpid(), SIGHUP), 0);
        EXPECT_EQ(
            waitForStat(keep, "catalog_reload_failures_total", [](double n) { return n > 0; }),
            1.0);
        EXPECT_EQ(serverStat(keep, "catalog_reloads_total"), 1.0);
        EXPECT_EQ(served(cc.port), (std::set<std::string>{"keep", "swap", "added"}));
        EXPECT_TRUE(frameArrives(keep, vk, 9));

        daemon.stop();
        thread.join();
    }
    logText = ::testing::internal::GetCapturedStderr();
    for (const char* line :
         {"catalog reload: drop removed", "catalog reload: added added",
          "catalog reload: swap reopened (store replaced by another file)",
          "catalog reload: 1 volume(s) unchanged, 3 served", "the old catalog is kept"})
        EXPECT_NE(logText.find(line), std::string::npos) << "no log line '" << line << "' in:\n"
                                                         << logText;
}

/// A frame's pixels at azimuth `az`.
std::vector<std::uint8_t> framePixels(client::Client& c, const protocol::VolumeInfo& v,
                                      std::uint32_t id) {
    c.setCamera(orbitCamera(v, 30.0, id));
    c.requestFrame();
    return c.nextFrame().rgba;
}

TEST(CatalogReload, ASessionOnAVolumeReopenedWithTheSameShapeMovesToTheNewStore) {
    TempDir dir;
    makeStore(dir.file("swap.bcs"), 32, brickstore::SynthKind::Vessels);
    const std::string config = dir.file("brickcastd.toml");
    writeConfig(config, {"swap"});
    TestDaemon daemon(DaemonConfig::load(config));
    client::ClientConfig cc = daemon.clientConfig();
    cc.timeoutMs = 20000;
    client::Client c(cc);
    const auto v = c.openVolume("swap");
    c.setRenderOptions(smallCpuFrames(32));
    const auto before = framePixels(c, v, 1);

    // Another store of the same name, voxel type (u8), dims and spacing, other voxels.
    makeStore(dir.file("swap.bcs"), 32, brickstore::SynthKind::Checker);
    daemon.daemon->reload();
    std::optional<protocol::VolumeOpened> moved;
    std::uint32_t request = 99;
    while (!moved) {
        auto m = c.nextMessage(&request);
        if (auto* e = std::get_if<protocol::Error>(&m)) {
            ADD_FAILURE() << "the session was sent " << protocol::errorName(std::uint16_t(e->code))
                          << ": " << e->message;
            break;
        }
        if (auto* o = std::get_if<protocol::VolumeOpened>(&m)) moved = *o;
    }
    ASSERT_TRUE(moved);
    EXPECT_EQ(request, 0u) << "the move is unasked";
    EXPECT_EQ(moved->info.name, "swap");
    EXPECT_EQ(moved->info.dims, v.dims);
    // Without opening it again: frames come, drawn from the new store with the same camera.
    const auto after = framePixels(c, v, 2);
    EXPECT_NE(after, before) << "the frame is still drawn from the old store";
    client::Client fresh(cc);
    const auto reopened = fresh.openVolume("swap");
    fresh.setRenderOptions(smallCpuFrames(32));
    EXPECT_EQ(framePixels(fresh, reopened, 3), after)
        << "the moved session's frame differs from a new session's on the new store";
}

/// Opens the write end of a FIFO when it goes, so that a reader blocked in open() goes on.
struct FifoWriter {
    std::string path;
    bool released = false;
    /// Opens the write end if a reader waits; true when one did.
    bool release() {
        const int fd = ::open(path.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
        if (fd < 0) return false; // ENXIO: no reader (yet)
        ::close(fd);
        return released = true;
    }
    ~FifoWriter() {
        for (int i = 0; i < 200 && !released && !release(); ++i)
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
};

TEST(CatalogReload, ClientsAreServedWhileAReloadWaitsForAFileToOpen) {
    TempDir dir;
    makeStore(dir.file("keep.bcs"), 32);
    const std::string config = dir.file("brickcastd.toml");
    writeConfig(config, {"keep"});
    TestDaemon daemon(DaemonConfig::load(config));
    client::ClientConfig cc = daemon.clientConfig();
    cc.timeoutMs = 3000;
    {
        // The config file read again is a FIFO: open() blocks until a writer comes, as long as
        // the test wants (a file on a slow or hung file system; a store that is no regular file
        // is refused without opening it).
        std::filesystem::remove(config);
        ASSERT_EQ(::mkfifo(config.c_str(), 0600), 0);
        FifoWriter slow{config}; // goes first: the reload ends before the daemon
        client::Client keep(cc);
        const auto vk = keep.openVolume("keep");
        keep.setRenderOptions(smallCpuFrames(32));
        ASSERT_TRUE(frameArrives(keep, vk, 1));
        daemon.daemon->reload();
        std::this_thread::sleep_for(std::chrono::milliseconds(300)); // the reload reaches open()
        const auto start = std::chrono::steady_clock::now();
        std::uint32_t frames = 0;
        try {
            for (std::uint32_t id = 2;
                 std::chrono::steady_clock::now() - start < std::chrono::milliseconds(1500); ++id)
                frames += frameArrives(keep, vk, id);
            EXPECT_EQ(served(cc.port), std::set<std::string>{"keep"});
        } catch (const std::exception& e) {
            ADD_FAILURE() << "a client was not served during the reload: " << e.what();
        }
        EXPECT_GE(frames, 3u);
        EXPECT_TRUE(slow.release()) << "the reload was not waiting in the config's open()";
    }
    // The FIFO held no config: the reload failed and the old catalog is kept.
    EXPECT_TRUE(waitForCatalog(cc.port, {"keep"}));
}

// A daemon told to stop while a reload waits in an open() (of its config file, a FIFO here; a
// hung network mount in the field) exits after a bounded wait and leaves the reload behind.
TEST(CatalogReload, StoppingDoesNotWaitForAReloadHungInAnOpen) {
    TempDir dir;
    makeStore(dir.file("keep.bcs"), 32);
    const std::string config = dir.file("brickcastd.toml");
    writeConfig(config, {"keep"});
    FifoWriter slow{config}; // outlives the daemon: the worker is released after
    double stopMs = 0;
    {
        auto daemon = std::make_unique<TestDaemon>(DaemonConfig::load(config));
        std::filesystem::remove(config);
        ASSERT_EQ(::mkfifo(config.c_str(), 0600), 0);
        daemon->daemon->reload();
        std::this_thread::sleep_for(std::chrono::milliseconds(300)); // the reload reaches open()
        const auto start = std::chrono::steady_clock::now();
        daemon.reset(); // stop(), run() returns, the daemon goes
        stopMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                     .count();
    }
    std::printf("[reload] stopped in %.0f ms with a reload waiting in open()\n", stopMs);
    EXPECT_LT(stopMs, 3000.0) << "the daemon waited for the hung reload";
    // The reload was still waiting: released now, its worker finds no daemon and ends.
    EXPECT_TRUE(slow.release()) << "the reload was not waiting in the config's open()";
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
}

} // namespace
} // namespace bc::server::test
