// An open store whose file changes under it: truncated, rewritten in place, or replaced by
// another file. Reads must turn into errors naming the store and what changed (never SIGBUS,
// never another store's voxels), and fileChange() tells a reload what happened.
#include "../TestSupport.h"
#include "brickstore/BrickStore.h"
#include "brickstore/Error.h"
#include "brickstore/Ingest.h"
#include "brickstore/Readers.h"

#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include <fcntl.h>
#include <sys/stat.h>

namespace bc::brickstore {
namespace {

std::string makeStore(const test::TempDir& dir, const std::string& name, std::uint64_t edge) {
    const std::string path = dir.file(name);
    auto source = makeSynthetic(SynthKind::Phantom, {edge, edge, edge}, 1);
    IngestConfig config;
    config.geometry = {16, 2, 8};
    ingest(*source, path, config);
    return path;
}

/// Every stored brick of the store, read; the first error's text, or "" when all read.
std::string readAll(const BrickStore& store) {
    std::vector<std::byte> buffer(store.brickBytes());
    for (std::uint64_t i = 0; i < store.layout().brickCount(); ++i) {
        const BrickKey key = store.layout().keyOf(i);
        if (!store.record(key).stored()) continue;
        try {
            store.readBrick(key, buffer);
            store.leafRanges(key);
        } catch (const StoreCorrupt& e) {
            return e.what();
        } catch (const StoreIoError& e) {
            return e.what();
        }
    }
    return {};
}

TEST(StoreChange, ATruncatedStoreFailsItsReadsNamingTheStoreAndTheSizes) {
    test::TempDir dir;
    const std::string path = makeStore(dir, "s.bcs", 64);
    auto store = BrickStore::open(path);
    ASSERT_EQ(readAll(*store), "");
    const auto bytes = std::filesystem::file_size(path);
    std::filesystem::resize_file(path, 8192);
    const std::string error = readAll(*store);
    EXPECT_NE(error.find(path), std::string::npos) << error;
    EXPECT_NE(error.find("size " + std::to_string(bytes) + " -> 8192 bytes"), std::string::npos)
        << error;
    EXPECT_EQ(store->fileChange(), "size " + std::to_string(bytes) + " -> 8192 bytes");
}

TEST(StoreChange, AStoreRewrittenInPlaceIsNotReadAsTheOtherVolume) {
    test::TempDir dir;
    const std::string path = makeStore(dir, "s.bcs", 64), other = makeStore(dir, "o.bcs", 48);
    auto store = BrickStore::open(path);
    const auto r = test::runCommand("cp " + other + " " + path); // same inode, new bytes
    ASSERT_EQ(r.exitCode, 0) << r.text;
    const std::string error = readAll(*store);
    EXPECT_NE(error.find(path + ": changed on disk since it was opened"), std::string::npos)
        << error;
    EXPECT_TRUE(store->fileChange());
}

TEST(StoreChange, AStoreReplacedByRenameKeepsServingTheOpenFileAndSaysSo) {
    test::TempDir dir;
    const std::string path = makeStore(dir, "s.bcs", 64);
    auto store = BrickStore::open(path);
    EXPECT_FALSE(store->fileChange());
    makeStore(dir, "s.bcs", 48); // ingest renames a new file into place
    EXPECT_EQ(readAll(*store), "") << "the open (now unlinked) file is still whole";
    EXPECT_EQ(store->fileChange(), "replaced by another file");
    std::filesystem::remove(path);
    ASSERT_TRUE(store->fileChange());
    EXPECT_EQ(store->fileChange()->rfind("gone: ", 0), 0u) << *store->fileChange();
}

TEST(StoreChange, ASameSizeRewriteThatKeepsTheModificationTimeIsSeen) {
    // What `cp -p`, `rsync --inplace -t` or `touch -r` leave: the same inode, size and
    // modification time, other bytes. Only the inode's change time, which no one can set, moves.
    test::TempDir dir;
    const std::string path = makeStore(dir, "s.bcs", 64);
    struct stat before {};
    ASSERT_EQ(::stat(path.c_str(), &before), 0);
    auto store = BrickStore::open(path);
    std::this_thread::sleep_for(std::chrono::milliseconds(50)); // past the clock's tick
    std::vector<std::uint8_t> bytes = test::readFile(path);
    bytes[bytes.size() / 2] ^= 0xff;
    {
        std::fstream file(path, std::ios::in | std::ios::out | std::ios::binary);
        file.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    }
    const timespec times[2] = {before.st_atim, before.st_mtim};
    ASSERT_EQ(::utimensat(AT_FDCWD, path.c_str(), times, 0), 0);
    struct stat after {};
    ASSERT_EQ(::stat(path.c_str(), &after), 0);
    ASSERT_EQ(after.st_ino, before.st_ino);
    ASSERT_EQ(after.st_size, before.st_size);
    ASSERT_EQ(after.st_mtim.tv_nsec, before.st_mtim.tv_nsec);
    ASSERT_EQ(after.st_mtim.tv_sec, before.st_mtim.tv_sec);
    ASSERT_TRUE(store->fileChange()) << "an in-place rewrite went unseen";
    EXPECT_EQ(store->fileChange()->rfind("rewritten in place", 0), 0u) << *store->fileChange();
}

} // namespace
} // namespace bc::brickstore
