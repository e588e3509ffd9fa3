// Little-endian fixed-width encoding of integers and floating-point values
// into byte buffers.
//
// Every integer on disk is little endian (docs/FORMAT.md). On a
// little-endian host the helpers copy the native integer; elsewhere they go
// through bytes, so the format stays right on a big-endian host. (GCC 12 does
// not merge the byte loop into one store: measured, the block encoder spent
// 8 instructions per byte on it.)
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>

namespace octocosm {

inline constexpr bool kHostIsLittleEndian = std::endian::native == std::endian::little;

inline void PutU16(std::uint8_t* out, std::uint16_t value) {
  if constexpr (kHostIsLittleEndian) {
    std::memcpy(out, &value, sizeof value);
    return;
  }
  out[0] = static_cast<std::uint8_t>(value);
  out[1] = static_cast<std::uint8_t>(value >> 8);
}

inline void PutU32(std::uint8_t* out, std::uint32_t value) {
  if constexpr (kHostIsLittleEndian) {
    std::memcpy(out, &value, sizeof value);
    return;
  }
  for (int i = 0; i < 4; ++i) out[i] = static_cast<std::uint8_t>(value >> (8 * i));
}

inline void PutU64(std::uint8_t* out, std::uint64_t value) {
  if constexpr (kHostIsLittleEndian) {
    std::memcpy(out, &value, sizeof value);
    return;
  }
  for (int i = 0; i < 8; ++i) out[i] = static_cast<std::uint8_t>(value >> (8 * i));
}

inline std::uint16_t GetU16(const std::uint8_t* in) {
  if constexpr (kHostIsLittleEndian) {
    std::uint16_t value;
    std::memcpy(&value, in, sizeof value);
    return value;
  }
  return static_cast<std::uint16_t>(in[0] | (in[1] << 8));
}

inline std::uint32_t GetU32(const std::uint8_t* in) {
  std::uint32_t value = 0;
  if constexpr (kHostIsLittleEndian) {
    std::memcpy(&value, in, sizeof value);
    return value;
  }
  for (int i = 3; i >= 0; --i) value = (value << 8) | in[i];
  return value;
}

inline std::uint64_t GetU64(const std::uint8_t* in) {
  std::uint64_t value = 0;
  if constexpr (kHostIsLittleEndian) {
    std::memcpy(&value, in, sizeof value);
    return value;
  }
  for (int i = 7; i >= 0; --i) value = (value << 8) | in[i];
  return value;
}

// Floating-point values as the little-endian bit patterns of their IEEE-754
// encodings (f32/f64 in docs/FORMAT.md).
inline void PutF32(std::uint8_t* out, float value) { PutU32(out, std::bit_cast<std::uint32_t>(value)); }
inline void PutF64(std::uint8_t* out, double value) { PutU64(out, std::bit_cast<std::uint64_t>(value)); }
inline float GetF32(const std::uint8_t* in) { return std::bit_cast<float>(GetU32(in)); }
inline double GetF64(const std::uint8_t* in) { return std::bit_cast<double>(GetU64(in)); }

}  // namespace octocosm
