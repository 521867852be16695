#pragma once
// Native voxel types kept in the store. Other input types are converted on read (and the
// reader says so in VolumeInfo::description).
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

namespace bc::brickstore {

enum class VoxelType : std::uint8_t { U8 = 1, U16 = 2, I16 = 3, F32 = 4 };

/// Bytes of one voxel of this type.
constexpr std::size_t voxelBytes(VoxelType t) {
    switch (t) {
    case VoxelType::U8:
        return 1;
    case VoxelType::U16:
        return 2;
    case VoxelType::I16:
        return 2;
    case VoxelType::F32:
        return 4;
    }
    return 0;
}

/// "u8", "u16", "i16", "f32".
std::string_view voxelTypeName(VoxelType t);
/// Parses "u8|u16|i16|f32" (also "uint8", "uint16", "int16", "float32", "float"); nullopt
/// otherwise.
std::optional<VoxelType> parseVoxelType(std::string_view name);
/// True when the byte value is one of the enum's values (for validating stored headers).
bool isValidVoxelType(std::uint8_t raw);

/// Reads voxel i of a native-typed buffer as double (exact for every VoxelType).
double voxelAsDouble(VoxelType t, const std::byte* data, std::size_t i);

} // namespace bc::brickstore
