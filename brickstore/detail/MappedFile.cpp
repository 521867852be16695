#include "brickstore/detail/MappedFile.h"

#include "brickstore/Error.h"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

namespace bc::brickstore::detail {

MappedFile::MappedFile(const std::string& path) {
    int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw StoreIoError(path + ": cannot open: " + std::strerror(errno));
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
        ::close(fd);
        throw StoreIoError(path + ": not a regular file");
    }
    mSize = static_cast<std::size_t>(st.st_size);
    if (mSize > 0) {
        void* p = ::mmap(nullptr, mSize, PROT_READ, MAP_SHARED, fd, 0);
        if (p == MAP_FAILED) {
            int err = errno;
            ::close(fd);
            throw StoreIoError(path + ": cannot map: " + std::strerror(err));
        }
        mData = static_cast<const std::byte*>(p);
    }
    ::close(fd);
}

MappedFile::~MappedFile() {
    if (mData) ::munmap(const_cast<std::byte*>(mData), mSize);
}

} // namespace bc::brickstore::detail
