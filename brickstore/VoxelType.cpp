#include "brickstore/VoxelType.h"

#include <cstring>

namespace bc::brickstore {

std::string_view voxelTypeName(VoxelType t) {
    switch (t) {
    case VoxelType::U8:
        return "u8";
    case VoxelType::U16:
        return "u16";
    case VoxelType::I16:
        return "i16";
    case VoxelType::F32:
        return "f32";
    }
    return "?";
}

std::optional<VoxelType> parseVoxelType(std::string_view n) {
    if (n == "u8" || n == "uint8" || n == "uchar") return VoxelType::U8;
    if (n == "u16" || n == "uint16" || n == "ushort") return VoxelType::U16;
    if (n == "i16" || n == "int16" || n == "short") return VoxelType::I16;
    if (n == "f32" || n == "float32" || n == "float") return VoxelType::F32;
    return std::nullopt;
}

bool isValidVoxelType(std::uint8_t raw) {
    return raw >= 1 && raw <= 4;
}

double voxelAsDouble(VoxelType t, const std::byte* data, std::size_t i) {
    switch (t) {
    case VoxelType::U8:
        return static_cast<double>(static_cast<std::uint8_t>(data[i]));
    case VoxelType::U16: {
        std::uint16_t v;
        std::memcpy(&v, data + 2 * i, 2);
        return v;
    }
    case VoxelType::I16: {
        std::int16_t v;
        std::memcpy(&v, data + 2 * i, 2);
        return v;
    }
    case VoxelType::F32: {
        float v;
        std::memcpy(&v, data + 4 * i, 4);
        return v;
    }
    }
    return 0.0;
}

} // namespace bc::brickstore
