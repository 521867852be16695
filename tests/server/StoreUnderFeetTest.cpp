// A store that changes under a running daemon (truncated, or overwritten in place by `cp`)
// fails that volume only: its client gets an Error naming the store, the daemon lives on and
// the client of another volume keeps receiving frames. And the start is strict: a configured
// store that is missing or corrupt stops the daemon, naming it, unless it is optional.
#include "ServerTestSupport.h"

#include "server/Catalog.h"
#include "server/Error.h"

#include <filesystem>
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

/// Changes the first store with `change` while both volumes are viewed; the first client must
/// get RenderFailed naming the store, the second keeps its frames.
void expectOnlyTheFirstVolumeFails(const std::function<void(const std::string&)>& change,
                                   const std::string& expectWhy) {
    TempDir dir;
    const std::string a = makeStore(dir, "first.bcs", 96), b = makeStore(dir, "second.bcs", 64);
    TestDaemon daemon(twoStores(a, b));
    client::Client first(daemon.clientConfig()), second(daemon.clientConfig());
    const auto va = first.openVolume("first"), vb = second.openVolume("second");
    auto options = smallCpuFrames(48);
    options.level = 0; // full resolution: more bricks than the host budget holds
    first.setRenderOptions(options);
    second.setRenderOptions(options);
    ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(frameOrError(first, va, 0, 1)));
    ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(frameOrError(second, vb, 0, 1)));

    change(a);

    std::optional<client::ServerError> error;
    for (std::uint32_t i = 2; i < 12 && !error; ++i) {
        auto r = frameOrError(first, va, 30.0 * i, i);
        if (auto* e = std::get_if<client::ServerError>(&r)) error = *e;
    }
    ASSERT_TRUE(error) << "the first client kept getting frames from a changed store";
    EXPECT_EQ(error->code(), protocol::ErrorCode::RenderFailed);
    EXPECT_FALSE(error->fatal());
    EXPECT_NE(std::string(error->what()).find(a), std::string::npos)
        << "the error does not name the store: " << error->what();
    EXPECT_NE(std::string(error->what()).find(expectWhy), std::string::npos) << error->what();
    for (std::uint32_t i = 2; i < 6; ++i) {
        auto r = frameOrError(second, vb, 30.0 * i, i);
        ASSERT_TRUE(std::holds_alternative<client::ReceivedFrame>(r))
            << "the other volume's client lost its frames: "
            << std::get<client::ServerError>(r).what();
    }
    // The daemon still accepts clients and still lists both volumes.
    client::Client third(daemon.clientConfig());
    EXPECT_EQ(third.listVolumes().size(), 2u);
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

} // namespace
} // namespace bc::server::test
