// Checksums of stored bytes: XXH3-64 (xxHash's XXH3_64bits, seed 0).
//
// XXH3 is chosen over CRC32C because it runs at memory bandwidth without
// special instructions and its 64 bits make an accidental match on a
// corrupted multi-megabyte block negligible. docs/FORMAT.md fixes the choice.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace octocosm {

// XXH3-64 of `bytes`.
std::uint64_t Checksum64(std::span<const std::uint8_t> bytes);

// XXH3-64 of `first` followed by `second`, without copying them together.
// Index pages checksum their header and entries around the checksum field.
std::uint64_t Checksum64(std::span<const std::uint8_t> first, std::span<const std::uint8_t> second);

// "0x" followed by 16 lowercase hex digits: how keys and checksums appear in
// error messages, so that they can be searched for in a hex dump.
std::string Hex64(std::uint64_t value);

}  // namespace octocosm
