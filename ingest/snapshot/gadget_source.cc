#include "ingest/snapshot/gadget_source.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <optional>
#include <sstream>

#include "base/error.h"
#include "ingest/snapshot/binary_file.h"
#include "ingest/snapshot/file_set.h"
#include "ingest/snapshot/gadget_format.h"
#include "ingest/snapshot/segmented_source.h"

namespace octocosm {
namespace {

// Where one per-particle quantity of one file lives, and how wide its values are.
struct Column {
  std::uint64_t offset = 0;  // payload offset of the block
  std::size_t width = 0;     // bytes per scalar: 4 or 8; 0 = block absent
};

struct GadgetFile {
  std::string path;
  GadgetFileStructure structure;
  Column position, velocity, id, mass;
  Column smoothing;  // HSML: one per gas (type 0) particle; absent in format 1 files
  // Index of the first particle of each type in POS/VEL/ID, and in MASS.
  std::array<std::uint64_t, kGadgetTypes> type_start{};
  std::array<std::uint64_t, kGadgetTypes> mass_start{};
};

// The width of the scalars of a block holding `values` of them, which must be
// 4 or 8 bytes each; throws naming the block otherwise.
std::size_t ScalarWidth(const std::string& path, const GadgetBlock& block, std::uint64_t values,
                        const std::string& expectation) {
  if (values == 0) return 4;
  if (block.payload_bytes == values * 4) return 4;
  if (block.payload_bytes == values * 8) return 8;
  throw Error::BadInput(path, "block " + block.name + " holds " + std::to_string(block.payload_bytes) +
                                  " bytes; expected " + expectation + " x (4 or 8) bytes");
}

Column FindColumn(const GadgetFile& file, const char* name, std::uint64_t values, const std::string& expectation,
                  bool required) {
  const GadgetBlock* block = file.structure.Find(name);
  if (block == nullptr) {
    if (required && values > 0) {
      throw Error::BadInput(file.path, std::string("missing block ") + name + ": expected " + expectation +
                                           " values for the particles the header declares");
    }
    return Column{};
  }
  return Column{block->payload_offset, ScalarWidth(file.path, *block, values, expectation)};
}

GadgetFile DescribeFile(const std::string& path) {
  GadgetFile file;
  file.path = path;
  BinaryFile binary(path);
  file.structure = ReadGadgetStructure(binary);
  const GadgetHeader& header = file.structure.header;
  std::uint64_t n = header.ParticleCount();
  std::uint64_t n_mass = header.MassBlockCount();
  std::string particles = std::to_string(n) + " particles";
  file.position = FindColumn(file, "POS", 3 * n, "3 x " + particles, true);
  file.velocity = FindColumn(file, "VEL", 3 * n, "3 x " + particles, false);
  file.id = FindColumn(file, "ID", n, "1 x " + particles, false);
  file.mass = FindColumn(file, "MASS", n_mass,
                         std::to_string(n_mass) + " particles of types with mass-table entry 0", true);
  // Smoothing lengths are found by name only: format 1 has no block names,
  // and which of its unnamed blocks would hold them depends on the options
  // the simulation code was built with. An HSML block of another length
  // than the gas particles' (a code that writes it for more types) is left
  // unread rather than guessed at; FillHeader records that.
  const GadgetBlock* hsml = file.structure.format == 2 ? file.structure.Find("HSML") : nullptr;
  const std::uint64_t gas = static_cast<std::uint64_t>(header.npart[0]);
  if (hsml != nullptr && gas > 0 && (hsml->payload_bytes == 4 * gas || hsml->payload_bytes == 8 * gas)) {
    file.smoothing = Column{hsml->payload_offset, static_cast<std::size_t>(hsml->payload_bytes / gas)};
  }
  // A type's table mass is every one of its particles' mass: checked here
  // once, for the types this file holds (the others' entries may be junk).
  for (int t = 0; t < kGadgetTypes; ++t) {
    const double mass = header.mass_table[t];
    if (header.npart[t] > 0 && !(std::isfinite(mass) && mass >= 0)) {
      std::ostringstream value;
      value << mass;
      throw Error::BadInput(path, "header field mass[" + std::to_string(t) + "] (the mass table) is " + value.str() +
                                      " for the " + std::to_string(header.npart[t]) +
                                      " particles of type " + std::to_string(t) +
                                      "; it must be finite and > 0, or 0 for masses in the MASS block");
    }
  }
  std::uint64_t start = 0, mass_start = 0;
  for (int t = 0; t < kGadgetTypes; ++t) {
    file.type_start[t] = start;
    file.mass_start[t] = mass_start;
    start += static_cast<std::uint64_t>(header.npart[t]);
    if (header.mass_table[t] == 0) mass_start += static_cast<std::uint64_t>(header.npart[t]);
  }
  return file;
}

class GadgetSource final : public SegmentedSource {
 public:
  GadgetSource(const std::string& any_file, const ReadOptions& options)
      : SegmentedSource(options.chunk_particles) {
    GadgetFile first = DescribeFile(any_file);
    std::vector<std::string> paths = ExpandFileSet(any_file, first.structure.header.num_files);
    for (const std::string& path : paths) files_.push_back(path == any_file ? first : DescribeFile(path));
    FillHeader(options);
  }

 protected:
  void AppendRange(const Segment& segment, std::uint64_t begin, std::size_t count, ParticleChunk& chunk) override {
    const GadgetFile& file = files_[segment.file];
    const BinaryFile& binary = OpenFile(segment.file);
    const int t = segment.type;
    const bool swap = file.structure.swap;
    const std::uint64_t index = file.type_start[t] + begin;
    const std::size_t old = chunk.size();

    ReadColumn(binary, file.position, 3 * index, 3 * count, "POS");
    chunk.position.resize(3 * (old + count));
    DecodeReals(buffer_.data(), 3 * count, file.position.width, swap, chunk.position.data() + 3 * old);
    if (FillsVelocity()) {
      ReadColumn(binary, file.velocity, 3 * index, 3 * count, "VEL");
      chunk.velocity.resize(3 * (old + count));
      DecodeReals(buffer_.data(), 3 * count, file.velocity.width, swap, chunk.velocity.data() + 3 * old);
    }
    if (FillsId()) {
      ReadColumn(binary, file.id, index, count, "ID");
      chunk.id.resize(old + count);
      DecodeUnsigned(buffer_.data(), count, file.id.width, swap, chunk.id.data() + old);
    }
    const double table_mass = file.structure.header.mass_table[t];
    if (table_mass != 0) {
      chunk.mass.resize(old + count, table_mass);
    } else {
      ReadColumn(binary, file.mass, file.mass_start[t] + begin, count, "MASS");
      chunk.mass.resize(old + count);
      DecodeReals(buffer_.data(), count, file.mass.width, swap, chunk.mass.data() + old);
    }
    chunk.type.resize(old + count, static_cast<std::uint8_t>(t));
    if (header_.has_smoothing) {
      chunk.smoothing.resize(old + count);  // 0, not given, for the types without
      if (t == 0) {
        ReadColumn(binary, file.smoothing, begin, count, "HSML");
        DecodeReals(buffer_.data(), count, file.smoothing.width, swap, chunk.smoothing.data() + old);
      }
    }
  }

  std::vector<MappableSegment> MappableSegments() const override {
    if (header_.has_smoothing) return {};  // a segment has no place for them
    std::vector<MappableSegment> mappable;
    for (const Segment& segment : segments_) {
      const GadgetFile& file = files_[segment.file];
      const int t = segment.type;
      const double mass = file.structure.header.mass_table[t];
      const bool plain = !file.structure.swap && file.position.width == 4 &&
                         (!header_.has_velocity || file.velocity.width == 4) && std::isfinite(mass) && mass > 0;
      if (!plain) return {};
      const std::uint64_t first = file.type_start[t];
      mappable.push_back(MappableSegment{segment.file, t, segment.count, mass, file.position.offset + 12 * first,
                                         file.velocity.offset + 12 * first, file.id.offset + file.id.width * first,
                                         file.id.width});
    }
    return mappable;
  }

  std::string DescribeParticle(const Segment& segment, std::uint64_t index) const override {
    return "particle type " + std::to_string(segment.type) + " particle " + std::to_string(index);
  }

  std::string DescribeSmoothing(const Segment&) const override { return "block HSML"; }

 private:
  void FillHeader(const ReadOptions& options) {
    const GadgetHeader& first = files_.front().structure.header;
    header_.format = files_.front().structure.format == 2 ? "gadget2" : "gadget1";
    std::vector<std::uint64_t> file_sums(kGadgetTypes, 0);
    bool all_velocity = true, all_id = true;
    bool any_gas = false, all_smoothing = true, any_hsml = false;
    for (std::size_t f = 0; f < files_.size(); ++f) {
      const GadgetFile& file = files_[f];
      header_.files.push_back(file.path);
      const GadgetHeader& h = file.structure.header;
      for (int t = 0; t < kGadgetTypes; ++t) file_sums[t] += static_cast<std::uint64_t>(h.npart[t]);
      if (h.ParticleCount() > 0) {
        all_velocity = all_velocity && file.velocity.width != 0;
        all_id = all_id && file.id.width != 0;
      }
      if (h.npart[0] > 0) {
        any_gas = true;
        all_smoothing = all_smoothing && file.smoothing.width != 0;
        any_hsml = any_hsml || file.structure.Find("HSML") != nullptr;
      }
      for (int t = 0; t < kGadgetTypes; ++t) {
        if (h.npart[t] > 0 && IsTypeSelected(options.types, t)) {
          segments_.push_back(Segment{f, t, static_cast<std::uint64_t>(h.npart[t])});
        }
      }
    }
    if (std::all_of(file_sums.begin(), file_sums.end(), [](std::uint64_t n) { return n == 0; })) {
      throw Error::BadInput(files_.front().path, "empty input: no file of the snapshot holds any particles");
    }
    std::vector<std::uint64_t> low(first.npart_total.begin(), first.npart_total.end());
    std::vector<std::uint64_t> high(first.npart_total_high.begin(), first.npart_total_high.end());
    ReconcileTypeTotals(files_.front().path, low, high, file_sums, header_.extra);
    CountSegments(kGadgetTypes);

    header_.has_velocity = options.read_velocity && all_velocity;
    header_.has_id = options.read_id && all_id;
    // Like velocities, for every file that holds gas or for none.
    const bool gas_read = any_gas && IsTypeSelected(options.types, 0);
    header_.has_smoothing = options.read_smoothing && gas_read && all_smoothing;
    if (header_.has_smoothing) {
      header_.extra["smoothing_lengths"] = "block HSML (gas)";
    } else if (options.read_smoothing && gas_read && any_hsml) {
      header_.extra["smoothing_lengths_not_read"] =
          "an HSML block is missing from a file with gas, or does not hold one value per gas particle";
    }
    const std::string& path = files_.front().path;
    header_.time = RequireFinite(path, "time", first.time);
    header_.redshift = RequireFinite(path, "redshift", first.redshift);
    SetBoxSize(path, "BoxSize", first.box_size, options);
    header_.omega0 = RequireFinite(path, "Omega0", first.omega0);
    header_.omega_lambda = RequireFinite(path, "OmegaLambda", first.omega_lambda);
    header_.hubble_param = RequireFinite(path, "HubbleParam", first.hubble_param);
    // GADGET has no comoving flag in the header; a redshift or a matter density
    // is only written by cosmological runs.
    header_.cosmological = first.redshift != 0 || first.omega0 != 0;
    if (header_.cosmological && header_.redshift == 0 && first.time > 0) {
      header_.redshift = RequireFinite(path, "time (1/a - 1 as the redshift)", 1 / first.time - 1);
    }

    nlohmann::json& extra = header_.extra;
    extra["mass_table"] = first.mass_table;
    extra["byte_order"] = files_.front().structure.swap == (std::endian::native == std::endian::little)
                              ? "big-endian"
                              : "little-endian";
    extra["num_files_in_header"] = first.num_files;
    extra["npart_total_in_header"] = first.npart_total;
    extra["flags"] = {{"sfr", first.flag_sfr},
                      {"feedback", first.flag_feedback},
                      {"cooling", first.flag_cooling},
                      {"stellarage", first.flag_stellarage},
                      {"metals", first.flag_metals},
                      {"entropy_instead_u", first.flag_entropy_instead_u}};
    extra["position_bytes"] = files_.front().position.width;
    if (header_.has_id) extra["id_bytes"] = files_.front().id.width;
  }

  const BinaryFile& OpenFile(std::size_t index) {
    if (!open_file_ || open_index_ != index) {
      open_file_.emplace(files_[index].path);
      open_index_ = index;
    }
    return *open_file_;
  }

  // Reads `values` scalars of `column`, starting at scalar `first`, into buffer_.
  void ReadColumn(const BinaryFile& binary, const Column& column, std::uint64_t first, std::size_t values,
                  const char* block) {
    buffer_.resize(values * column.width);
    binary.ReadAt(column.offset + first * column.width, buffer_.data(), buffer_.size(),
                  std::string("block ") + block);
  }

  std::vector<GadgetFile> files_;
  std::optional<BinaryFile> open_file_;
  std::size_t open_index_ = 0;
  std::vector<std::uint8_t> buffer_;
};

}  // namespace

std::unique_ptr<ParticleSource> OpenGadgetSnapshot(const std::string& file, const ReadOptions& options) {
  return std::make_unique<GadgetSource>(file, options);
}

}  // namespace octocosm
