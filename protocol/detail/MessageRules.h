#pragma once
// The value rules of PROTOCOL.md, shared by the encoder (which throws on a violation) and the
// decoder (which answers it with an Error), so both sides enforce one set of rules with one
// wording. Private to bc_protocol.
#include "protocol/Messages.h"
#include "protocol/Wire.h"

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace bc::protocol::detail {

/// A broken rule: the Error code that answers it and a text naming message and field.
struct Violation {
    ErrorCode code;
    std::string text;
};

/// A field name, with an index for array elements ("eye[1]", "codecs[3]").
struct Field {
    Field(const char* fieldName) : name(fieldName) {}
    Field(const char* fieldName, std::size_t fieldIndex)
        : name(fieldName), index(static_cast<std::ptrdiff_t>(fieldIndex)) {}
    const char* name;
    std::ptrdiff_t index = -1;
};

/// Collects the first violation of one message. Texts are built only on failure, so checking
/// a valid message allocates nothing.
class Rules {
  public:
    explicit Rules(const char* message) : mMessage(message) {}

    /// Fields named from now on belong to list[index] ("VolumeList.volumes[2].name"), or to
    /// the sub-struct `list` when index is -1 ("VolumeOpened.info.name").
    void item(const char* list, std::ptrdiff_t index = -1);
    /// Records a violation unless one is recorded already.
    void fail(ErrorCode code, Field field, std::string_view text);
    bool ok() const { return !mViolation; }
    std::optional<Violation> take() { return std::move(mViolation); }

    /// lo <= v <= hi (integers).
    void intRange(Field field, std::uint64_t v, std::uint64_t lo, std::uint64_t hi);
    /// An enum's raw value is one of 0..maxValue.
    void enumValue(Field field, std::uint64_t raw, std::uint64_t maxValue);
    /// v is finite.
    void finite(Field field, double v);
    void finite(const char* field, std::span<const double> v);
    /// v lies in the interval from lo to hi; open ends exclude the bound (NaN never lies in it).
    void realRange(Field field, double v, double lo, double hi, bool loOpen, bool hiOpen);
    void realRange(Field field, float v, double lo, double hi, bool loOpen, bool hiOpen);
    /// v has no bit outside allowedMask.
    void bits(Field field, std::uint64_t v, std::uint64_t allowedMask);
    /// A str field: valid UTF-8 of minBytes..maxBytes.
    void text(Field field, std::string_view s, std::size_t minBytes, std::size_t maxBytes);
    /// A catalog name: 1..64 of A-Z a-z 0-9 . _ -, not starting with '.'.
    void volumeName(Field field, std::string_view s);
    /// A list of n entries is within maxEntries.
    void count(Field field, std::size_t n, std::size_t maxEntries);

  private:
    std::string fieldText(Field field) const;
    void failRange(Field field, const std::string& value, double lo, double hi, bool loOpen,
                   bool hiOpen);
    const char* mMessage;
    const char* mList = nullptr;
    std::ptrdiff_t mItem = -1;
    std::optional<Violation> mViolation;
};

/// The first rule of PROTOCOL.md that `m` breaks, or nullopt.
std::optional<Violation> firstViolation(const Message& m);

/// Bytes of the valid UTF-8 character at s[i] (1..4), 0 if none starts there.
std::size_t utf8CharBytes(std::string_view s, std::size_t i);
/// A peer's string for an error text: quoted, printable ASCII, at most ~40 characters shown.
std::string quoted(std::string_view s);
/// "0x1f".
std::string hex(std::uint64_t v);
/// Shortest decimal form that reads back as v ("0.5", "nan", "inf").
std::string number(double v);
/// Shortest decimal that reads back as the float v ("0.99", not "0.9900000095367432").
std::string number(float v);

} // namespace bc::protocol::detail
