#include "brickstore/detail/RegularFile.h"

#include "brickstore/Error.h"

#include <cerrno>
#include <cstring>
#include <filesystem>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace bc::brickstore::detail {

std::string fileKindText(mode_t mode) {
    switch (mode & S_IFMT) {
    case S_IFREG:
        return "a regular file";
    case S_IFIFO:
        return "a FIFO";
    case S_IFSOCK:
        return "a socket";
    case S_IFCHR:
        return "a character device";
    case S_IFBLK:
        return "a block device";
    case S_IFDIR:
        return "a folder";
    case S_IFLNK:
        return "a symbolic link";
    default:
        return "an unknown kind of file";
    }
}

std::optional<std::string> notRegularFile(const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) return std::string(std::strerror(errno));
    if (S_ISREG(st.st_mode)) return std::nullopt;
    return "not a regular file (" + fileKindText(st.st_mode) + ")";
}

int openRegularFile(const std::string& path, std::string& why) {
    if (auto bad = notRegularFile(path)) {
        why = *bad;
        return -1;
    }
    const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) {
        why = std::strerror(errno);
        return -1;
    }
    struct stat st {};
    const bool statted = ::fstat(fd, &st) == 0;
    const int flags = ::fcntl(fd, F_GETFL);
    if (statted && S_ISREG(st.st_mode) && flags >= 0 &&
        ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK) == 0)
        return fd;
    why = !statted || S_ISREG(st.st_mode) ? std::string(std::strerror(errno))
                                          : "not a regular file (" + fileKindText(st.st_mode) + ")";
    ::close(fd);
    return -1;
}

void requireRegularFile(const std::string& path) {
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0 || S_ISREG(st.st_mode)) return;
    throw FormatError(path, "path", "not a regular file (" + fileKindText(st.st_mode) + ")");
}

mode_t fileMode(const std::string& path) {
    struct stat st {};
    return ::stat(path.c_str(), &st) == 0 ? st.st_mode : 0;
}

std::uint64_t fileOrFolderBytes(const std::string& path) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (!fs::is_directory(path, ec)) {
        const std::uint64_t bytes = fs::file_size(path, ec);
        return ec ? 0 : bytes;
    }
    std::uint64_t bytes = 0;
    for (const auto& entry : fs::directory_iterator(path, ec)) {
        std::error_code sizeError;
        if (entry.is_regular_file(sizeError)) bytes += entry.file_size(sizeError);
    }
    return bytes;
}

} // namespace bc::brickstore::detail
