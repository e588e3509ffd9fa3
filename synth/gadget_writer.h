// Writes GADGET-2 snapshot files (Springel 2005; GADGET-2 user guide,
// section 6), little endian, in format 1 (plain Fortran records) or format 2
// (each record preceded by a 4-character block name), holding particles of
// one type whose mass is given in the header's mass table (so there is no
// MASS block), as both the particle-mesh mode and the scale mode produce.
//
// File layout, every record framed by int32 byte counts on both sides:
//   [format 2 only: int32 8, "HEAD", int32 256+8, int32 8]
//   int32 256, header (256 bytes, see EncodeGadgetHeader), int32 256
//   [format 2: int32 8, "POS ", int32 12n+8, int32 8]  int32 12n, n x float32[3], int32 12n
//   [format 2: int32 8, "VEL ", int32 12n+8, int32 8]  int32 12n, n x float32[3], int32 12n
//   [format 2: int32 8, "ID  ", int32 wn+8,  int32 8]  int32 wn,  n x uint{w*8}, int32 wn
// with w = 4 (uint32 IDs) when the snapshot's total count is below 2^32, else
// 8. Positions are in the header's length unit, velocities are peculiar
// velocity / sqrt(a) in km/s (GADGET's convention for comoving runs).
//
// Writing is streaming: particles arrive in chunks in file order, and each
// chunk goes straight to its place in the three blocks, so memory stays at
// one chunk. Files are written as NAME.tmp and renamed to NAME only once the
// whole snapshot (all its files) is complete, so a crashed or failed run
// never leaves a snapshot that looks whole. All failures throw
// octocosm::Error naming the file.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "base/interrupt_cleanup.h"

namespace octocosm::synth {

enum class GadgetFormat { kFormat1 = 1, kFormat2 = 2 };

// The 256-byte GADGET-2 header ("io_header" in GADGET-2's allvars.h).
struct GadgetHeader {
  std::array<std::uint32_t, 6> npart{};        // particles of each type in this file
  std::array<double, 6> mass{};                // per-type mass, 1e10 Msun/h; 0 means "in MASS block"
  double time = 0.0;                           // expansion factor a
  double redshift = 0.0;
  std::int32_t flag_sfr = 0;
  std::int32_t flag_feedback = 0;
  std::array<std::uint64_t, 6> npart_total{};  // over all files; stored as low word + high word
  std::int32_t flag_cooling = 0;
  std::int32_t num_files = 1;
  double box_size = 0.0;
  double omega0 = 0.0;
  double omega_lambda = 0.0;
  double hubble_param = 0.0;
  std::int32_t flag_stellarage = 0;
  std::int32_t flag_metals = 0;
  std::int32_t flag_entropy_instead_u = 0;
};

// Byte offsets inside the 256-byte header, for readers and tests.
inline constexpr std::size_t kGadgetHeaderSize = 256;
inline constexpr std::size_t kHeaderNpartOffset = 0;           // uint32[6]
inline constexpr std::size_t kHeaderMassOffset = 24;           // double[6]
inline constexpr std::size_t kHeaderTimeOffset = 72;           // double
inline constexpr std::size_t kHeaderRedshiftOffset = 80;       // double
inline constexpr std::size_t kHeaderFlagSfrOffset = 88;        // int32
inline constexpr std::size_t kHeaderFlagFeedbackOffset = 92;   // int32
inline constexpr std::size_t kHeaderNpartTotalOffset = 96;     // uint32[6], low words
inline constexpr std::size_t kHeaderFlagCoolingOffset = 120;   // int32
inline constexpr std::size_t kHeaderNumFilesOffset = 124;      // int32
inline constexpr std::size_t kHeaderBoxSizeOffset = 128;       // double
inline constexpr std::size_t kHeaderOmega0Offset = 136;        // double
inline constexpr std::size_t kHeaderOmegaLambdaOffset = 144;   // double
inline constexpr std::size_t kHeaderHubbleParamOffset = 152;   // double
inline constexpr std::size_t kHeaderFlagStellarAgeOffset = 160;
inline constexpr std::size_t kHeaderFlagMetalsOffset = 164;
inline constexpr std::size_t kHeaderNpartTotalHighOffset = 168;  // uint32[6], high words
inline constexpr std::size_t kHeaderFlagEntropyOffset = 192;
// Bytes 196..255 are zero padding.

std::array<std::uint8_t, kGadgetHeaderSize> EncodeGadgetHeader(const GadgetHeader& header);

// One GADGET file. Usually reached through GadgetSnapshotWriter.
class GadgetFileWriter {
 public:
  // Creates `path`.tmp and writes the header and all record markers. The
  // particles of the file are those counted in header.npart (one type with a
  // mass-table entry > 0); id_bytes is 4 or 8.
  GadgetFileWriter(std::string path, const GadgetHeader& header, GadgetFormat format, int id_bytes);
  // Removes the temporary file unless Commit() ran; so does SIGINT, SIGTERM
  // or SIGHUP (base/interrupt_cleanup.h).
  ~GadgetFileWriter();
  GadgetFileWriter(const GadgetFileWriter&) = delete;
  GadgetFileWriter& operator=(const GadgetFileWriter&) = delete;

  // Writes the next particles: positions and velocities x,y,z interleaved
  // (3 per particle), ids one per particle. Throws InvalidArgument when the
  // sizes disagree or the file would receive more particles than announced.
  void Append(std::span<const float> positions, std::span<const float> velocities,
              std::span<const std::uint64_t> ids);

  std::uint64_t expected() const { return expected_; }
  std::uint64_t written() const { return written_; }

  // Checks that every announced particle arrived, flushes the file to disk
  // and closes it (still under the temporary name).
  void Close();
  // Renames the closed temporary file to its final name.
  void Commit();

  const std::string& path() const { return path_; }

 private:
  void WriteAt(std::uint64_t offset, const void* data, std::size_t size);

  std::string path_;
  std::string temp_path_;
  int fd_ = -1;
  int id_bytes_;
  std::uint64_t expected_;
  std::uint64_t written_ = 0;
  std::uint64_t position_payload_ = 0;  // file offsets of the first payload byte of each block
  std::uint64_t velocity_payload_ = 0;
  std::uint64_t id_payload_ = 0;
  bool closed_ = false;
  bool committed_ = false;
  // The temporary file goes if a signal ends the program (synth's runs are long).
  std::optional<RemoveOnInterrupt> remove_on_interrupt_;
};

// What a whole snapshot (possibly several files) records about itself.
struct GadgetSnapshotInfo {
  std::uint64_t particle_count = 0;
  int particle_type = 1;          // GADGET type 1 = dark matter ("halo")
  double particle_mass = 0.0;     // 1e10 Msun/h, > 0
  double time = 1.0;              // a
  double redshift = 0.0;
  double box_size = 0.0;          // in the snapshot's length unit
  double omega0 = 0.0;
  double omega_lambda = 0.0;
  double hubble_param = 0.0;
  int num_files = 1;
};

// A snapshot split over num_files files named `base` (one file) or
// `base`.0, `base`.1, ... (several). File f holds particles
// [count*f/num_files, count*(f+1)/num_files) of the stream.
class GadgetSnapshotWriter {
 public:
  GadgetSnapshotWriter(std::string base, const GadgetSnapshotInfo& info, GadgetFormat format);
  ~GadgetSnapshotWriter();
  GadgetSnapshotWriter(const GadgetSnapshotWriter&) = delete;
  GadgetSnapshotWriter& operator=(const GadgetSnapshotWriter&) = delete;

  // Same contract as GadgetFileWriter::Append; chunks may cross file bounds.
  void Append(std::span<const float> positions, std::span<const float> velocities,
              std::span<const std::uint64_t> ids);
  // Checks the count, closes every file and renames them all into place.
  void Finish();

  // Final names of the files, in order.
  const std::vector<std::string>& paths() const { return paths_; }

 private:
  void OpenFile(int index);

  std::string base_;
  GadgetSnapshotInfo info_;
  GadgetFormat format_;
  int id_bytes_;
  std::vector<std::string> paths_;
  std::vector<std::unique_ptr<GadgetFileWriter>> files_;  // closed ones wait here for the rename
  int current_ = -1;
  std::uint64_t written_ = 0;
  bool finished_ = false;
};

// Converts a position in [0, box) to float32 so that it stays below box:
// rounding a double just under box to the nearest float can give box itself.
float PositionToFloat(double position, float box);

}  // namespace octocosm::synth
