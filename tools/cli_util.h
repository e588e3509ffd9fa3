// Small helpers shared by the subcommands: parsing of sizes and lists.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace octocosm {

// "4G", "512M", "64K", "1048576", "2GiB" -> bytes. Throws Error::InvalidArgument.
std::uint64_t ParseByteSize(const std::string& text, const std::string& flag);
// "1,2,5" -> {1, 2, 5}. Throws Error::InvalidArgument.
std::vector<double> ParseNumberList(const std::string& text, const std::string& flag);
// 123456789 -> "117.7 MiB".
std::string HumanBytes(double bytes);

}  // namespace octocosm
