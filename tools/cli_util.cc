#include "tools/cli_util.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "base/error.h"

namespace octocosm {

std::uint64_t ParseByteSize(const std::string& text, const std::string& flag) {
  std::size_t end = 0;
  double value = 0;
  try {
    value = std::stod(text, &end);
  } catch (const std::exception&) {
    throw Error::InvalidArgument(flag + " '" + text + "': expected a size such as 512M, 4G or 65536");
  }
  std::string unit = text.substr(end);
  for (char& c : unit) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  if (unit.size() > 1 && (unit.ends_with("IB") || unit.ends_with("B"))) unit = unit.substr(0, 1);
  double scale = 1;
  if (unit.empty() || unit == "B") scale = 1;
  else if (unit == "K") scale = 1024.0;
  else if (unit == "M") scale = 1024.0 * 1024;
  else if (unit == "G") scale = 1024.0 * 1024 * 1024;
  else if (unit == "T") scale = 1024.0 * 1024 * 1024 * 1024;
  else throw Error::InvalidArgument(flag + " '" + text + "': unknown unit '" + text.substr(end) + "' (use K, M, G or T)");
  const double bytes = value * scale;
  if (!std::isfinite(bytes) || bytes < 0 || bytes > 1.8e19) {
    throw Error::InvalidArgument(flag + " '" + text + "': out of range");
  }
  return static_cast<std::uint64_t>(bytes);
}

std::vector<double> ParseNumberList(const std::string& text, const std::string& flag) {
  std::vector<double> values;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ',')) {
    std::size_t end = 0;
    try {
      values.push_back(std::stod(item, &end));
    } catch (const std::exception&) {
      end = 0;
    }
    if (end == 0 || end != item.size()) throw Error::InvalidArgument(flag + " '" + text + "': '" + item + "' is not a number");
  }
  return values;
}

std::string HumanBytes(double bytes) {
  static const char* const kUnits[] = {"B", "KiB", "MiB", "GiB", "TiB"};
  int i = 0;
  while (bytes >= 1024.0 && i < 4) {
    bytes /= 1024.0;
    ++i;
  }
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, i == 0 ? "%.0f %s" : "%.1f %s", bytes, kUnits[i]);
  return buffer;
}

}  // namespace octocosm
