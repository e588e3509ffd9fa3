// GADGET binary snapshots written by tests: every variant the reader takes
// (format 1/2, either byte order, 4/8-byte reals and IDs, mass table or MASS
// block) from particle values given in file order.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

namespace octocosm {

struct GadgetSpec {
  int format = 1;
  bool big_endian = false;
  int real_bytes = 4;  // POS, VEL, MASS
  int id_bytes = 4;
  std::array<std::int32_t, 6> npart{};
  std::array<double, 6> mass_table{};
  std::optional<std::array<std::uint32_t, 6>> total;  // default: npart
  std::array<std::uint32_t, 6> total_high{};
  std::int32_t num_files = 1;
  double time = 0.5, redshift = 1.0, box = 100;
  bool write_velocity = true, write_ids = true, write_mass = true;
  // Per-particle data in file order (type 0 first).
  std::vector<double> position, velocity, mass_block;
  std::vector<std::uint64_t> ids;
  // Written as an HSML block after U when not empty (format 2 names it;
  // in format 1 it is one more unnamed record), as GADGET-2 writes gas
  // smoothing lengths: one per type 0 particle.
  std::vector<double> hsml;
};

class Encoder {
 public:
  explicit Encoder(bool big_endian) : big_endian_(big_endian) {}
  template <typename T>
  void Put(T value) {
    std::uint8_t bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    if (big_endian_) std::reverse(bytes, bytes + sizeof(T));
    out_.append(reinterpret_cast<char*>(bytes), sizeof(T));
  }
  void Raw(const std::string& bytes) { out_ += bytes; }
  std::string& bytes() { return out_; }

 private:
  bool big_endian_;
  std::string out_;
};

inline std::string EncodeGadget(const GadgetSpec& spec) {
  Encoder file(spec.big_endian);
  auto record = [&](const char* name, const std::string& payload) {
    if (spec.format == 2) {
      file.Put<std::int32_t>(8);
      std::string tag = std::string(name) + "    ";
      file.Raw(tag.substr(0, 4));
      file.Put<std::int32_t>(static_cast<std::int32_t>(payload.size() + 8));
      file.Put<std::int32_t>(8);
    }
    file.Put<std::int32_t>(static_cast<std::int32_t>(payload.size()));
    file.Raw(payload);
    file.Put<std::int32_t>(static_cast<std::int32_t>(payload.size()));
  };
  Encoder header(spec.big_endian);
  for (auto n : spec.npart) header.Put<std::int32_t>(n);
  for (auto m : spec.mass_table) header.Put<double>(m);
  header.Put<double>(spec.time);
  header.Put<double>(spec.redshift);
  header.Put<std::int32_t>(0);
  header.Put<std::int32_t>(0);
  for (int t = 0; t < 6; ++t) header.Put<std::uint32_t>(spec.total ? (*spec.total)[t] : static_cast<std::uint32_t>(spec.npart[t]));
  header.Put<std::int32_t>(0);
  header.Put<std::int32_t>(spec.num_files);
  header.Put<double>(spec.box);
  header.Put<double>(0.3);
  header.Put<double>(0.7);
  header.Put<double>(0.7);
  header.Put<std::int32_t>(0);
  header.Put<std::int32_t>(0);
  for (auto h : spec.total_high) header.Put<std::uint32_t>(h);
  header.bytes().resize(256, '\0');
  record("HEAD", header.bytes());

  auto reals = [&](const std::vector<double>& values) {
    Encoder e(spec.big_endian);
    for (double v : values) {
      if (spec.real_bytes == 4) {
        e.Put<float>(static_cast<float>(v));
      } else {
        e.Put<double>(v);
      }
    }
    return e.bytes();
  };
  record("POS", reals(spec.position));
  if (spec.write_velocity) record("VEL", reals(spec.velocity));
  if (spec.write_ids) {
    Encoder e(spec.big_endian);
    for (auto id : spec.ids) {
      if (spec.id_bytes == 4) {
        e.Put<std::uint32_t>(static_cast<std::uint32_t>(id));
      } else {
        e.Put<std::uint64_t>(id);
      }
    }
    record("ID", e.bytes());
  }
  if (spec.write_mass && !spec.mass_block.empty()) record("MASS", reals(spec.mass_block));
  record("U", std::string(16, '\0'));  // a block the reader must skip
  if (!spec.hsml.empty()) record("HSML", reals(spec.hsml));
  return file.bytes();
}

inline void WriteBytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace octocosm
