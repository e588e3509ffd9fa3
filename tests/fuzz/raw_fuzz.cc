// Fuzz target: the raw binary reader (ingest/snapshot/raw_source.h) and its
// layout grammar (RawLayout::Parse). The input is the layout string, a
// newline, and then the file's bytes, so that the fuzzer varies both.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

#include "base/error.h"
#include "tests/fuzz/fuzz_target.h"
#include "tests/fuzz/snapshot_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto* end = data + size;
  const auto* newline = std::find(data, end, static_cast<std::uint8_t>('\n'));
  if (newline == end) return 0;
  octocosm::ReadOptions options;
  options.format = "raw";
  try {
    options.raw = octocosm::RawLayout::Parse(
        std::string_view(reinterpret_cast<const char*>(data), static_cast<std::size_t>(newline - data)));
  } catch (const octocosm::Error& e) {
    octocosm::fuzz::Refused(e);
    return 0;
  }
  octocosm::fuzz::ReadSnapshotBytes(newline + 1, static_cast<std::size_t>(end - newline - 1), "particles.raw",
                                    options);
  return 0;
}

namespace octocosm::fuzz {
namespace {

template <typename T>
void Put(std::string& out, T value, bool big_endian = false) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if (big_endian) std::reverse(bytes, bytes + sizeof(T));
  out.append(bytes, sizeof(T));
}

}  // namespace

std::vector<Seed> Seeds(const std::string&) {
  std::vector<Seed> seeds;
  {
    std::string bytes = "x,y,z:f32\n";
    for (int i = 0; i < 6; ++i) {
      for (int axis = 0; axis < 3; ++axis) Put<float>(bytes, static_cast<float>(i + axis) * 0.5f);
    }
    seeds.push_back({"f32-positions", bytes});
  }
  {
    std::string bytes = "xyz:f64,vel:f32x3,mass:f64,id:u64\n";
    for (int i = 0; i < 5; ++i) {
      for (int axis = 0; axis < 3; ++axis) Put<double>(bytes, i * 1.25 + axis);
      for (int axis = 0; axis < 3; ++axis) Put<float>(bytes, static_cast<float>(axis - i));
      Put<double>(bytes, 0.5 + i);
      Put<std::uint64_t>(bytes, 1000 + static_cast<std::uint64_t>(i));
    }
    seeds.push_back({"f64-everything", bytes});
  }
  {
    std::string bytes = ">xyz:f32,skip:f32x3,id:i64\n";
    for (int i = 0; i < 4; ++i) {
      for (int axis = 0; axis < 3; ++axis) Put<float>(bytes, static_cast<float>(i * 3 + axis), true);
      for (int axis = 0; axis < 3; ++axis) Put<float>(bytes, 9.0f, true);
      Put<std::int64_t>(bytes, i, true);
    }
    seeds.push_back({"big-endian-skip", bytes});
  }
  return seeds;
}

}  // namespace octocosm::fuzz
