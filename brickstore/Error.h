#pragma once
// Typed errors of the brickstore module. Expected outcomes (a cache miss, a brick that is
// not stored) are return values; these are for bad files and broken stores.
#include <stdexcept>
#include <string>

namespace bc::brickstore {

/// An input file (raw, NRRD, NIfTI, DICOM, VDB) or a command-line volume description is
/// unusable. what() names the file and the field at fault: "FILE: FIELD: why".
class FormatError : public std::runtime_error {
  public:
    FormatError(const std::string& file, const std::string& field, const std::string& why)
        : std::runtime_error(file + ": " + field + ": " + why), mFile(file), mField(field) {}
    const std::string& file() const { return mFile; }
    const std::string& field() const { return mField; }

  private:
    std::string mFile;
    std::string mField;
};

/// A brick store is truncated, inconsistent or fails a checksum. what() names the store
/// and, where one brick is at fault, that brick ("L0 (3,1,2)").
class StoreCorrupt : public std::runtime_error {
  public:
    explicit StoreCorrupt(const std::string& what) : std::runtime_error(what) {}
};

/// The store could not be written or opened for a reason outside its contents (I/O, disk
/// full, permissions).
class StoreIoError : public std::runtime_error {
  public:
    explicit StoreIoError(const std::string& what) : std::runtime_error(what) {}
};

} // namespace bc::brickstore
