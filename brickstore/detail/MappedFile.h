#pragma once
// Read-only memory map of a whole file (POSIX). Move-only owner.
#include <cstddef>
#include <span>
#include <string>

namespace bc::brickstore::detail {

class MappedFile {
  public:
    /// @throw StoreIoError naming the path when it cannot be opened or mapped.
    explicit MappedFile(const std::string& path);
    ~MappedFile();
    MappedFile(const MappedFile&) = delete;
    MappedFile& operator=(const MappedFile&) = delete;
    std::span<const std::byte> bytes() const { return {mData, mSize}; }

  private:
    const std::byte* mData = nullptr;
    std::size_t mSize = 0;
};

} // namespace bc::brickstore::detail
