// Streaming readers for N-body snapshots: the input side of `octocosm ingest`.
//
// OpenSnapshot() detects the format of a snapshot (GADGET format 1 or 2 in
// either byte order, HDF5 in the GADGET-4 / AREPO / SWIFT layout, or, when
// asked for explicitly, raw binary records and CSV), finds every file of a
// multi-file snapshot, checks the headers against each other, and returns a
// ParticleSource that hands out the particles in ParticleChunk batches.
//
// Memory is bounded by ReadOptions::chunk_particles whatever the size of the
// input: nothing reads a whole file. A source can be rewound, because the
// octree builder makes at least two passes (bounds and counts, then
// distribution). docs/INPUT_FORMATS.md describes what is read and how each
// quirk of real files is handled.
//
// Errors: malformed input throws Error::BadInput naming the file, the block or
// dataset, and what was expected; every number taken from a header is checked
// before it is used (finite; box size >= 0; counts the file can hold); a file that cannot be opened or read throws
// Error::Io or Error::NotFound; impossible options throw
// Error::InvalidArgument. Nothing here exits or aborts.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "index/particle_chunk.h"

namespace octocosm {

// What the manifest records about an input snapshot.
struct SnapshotHeader {
  std::string format;              // "gadget1", "gadget2", "hdf5-gadget", "hdf5-swift", "raw", "csv"
  std::vector<std::string> files;  // every file read, in reading order
  double time = 0;                 // scale factor a in cosmological runs, else simulation time
  double redshift = 0;             // from the header, or 1/a - 1 when cosmological and absent
  // 0 = not periodic / unknown. Every particle lies within it, give or take
  // kPeriodicBoxTolerance of it.
  double box_size = 0;
  // Particles per type over all files, after type selection (unselected types
  // count 0). Its length is the number of types of the format (6 for GADGET,
  // NTYPES for HDF5, 1 for raw and CSV).
  std::vector<std::uint64_t> count_per_type;
  std::uint64_t total_count = 0;  // sum of count_per_type
  bool has_velocity = false;      // chunks carry velocities
  bool has_id = false;            // chunks carry IDs
  // Chunks carry smoothing lengths (ParticleChunk::smoothing): the file's
  // own, for the particle types that have them (0 for the others).
  bool has_smoothing = false;
  bool cosmological = false;      // comoving integration (then time is the scale factor)
  double omega0 = 0, omega_lambda = 0, hubble_param = 0;  // 0 when unknown
  nlohmann::json extra = nlohmann::json::object();  // mass table, flags, units, quirks found
};

// The record layout of a raw binary file; see RawLayout::Parse for the grammar.
struct RawColumn {
  enum class Field { kX, kY, kZ, kVx, kVy, kVz, kMass, kId, kSkip };
  enum class Scalar { kF32, kF64, kU32, kU64, kI32, kI64 };
  Field field;
  Scalar scalar;
  std::size_t offset = 0;  // byte offset inside a record
};

struct RawLayout {
  std::vector<RawColumn> columns;  // one per scalar value in a record
  std::size_t record_bytes = 0;
  bool big_endian = false;
  std::string text;  // the layout string it was parsed from

  bool empty() const { return columns.empty(); }
  bool has(RawColumn::Field field) const;

  // Parses a layout string (the grammar is in docs/INPUT_FORMATS.md):
  //   layout  := [ "<" | ">" ] column { "," column }      ">" = big endian
  //   column  := name [ ":" scalar [ "x" count ] ]
  //   name    := x | y | z | vx | vy | vz | mass | id | skip | xyz | vel | pos
  //   scalar  := f32 | f64 | u32 | u64 | i32 | i64
  // A scalar applies to its column and to the untyped columns right before it,
  // so "x,y,z:f32" declares three float32 columns. "xyz"/"pos" and "vel" expand
  // to three columns; "skip:f32x2" skips 8 bytes. x, y and z are required;
  // vx, vy, vz come all three or not at all. Throws Error::InvalidArgument.
  static RawLayout Parse(std::string_view text);
};

struct CsvOptions {
  // Field separator: ',' or ' ' (any run of spaces and tabs). 0 = detect from
  // the header row (comma if it has one, else whitespace).
  char delimiter = 0;
};

struct ReadOptions {
  // "auto" detects GADGET and HDF5 from the bytes, and CSV from a ".csv"
  // name; "gadget", "hdf5", "raw" (needs `raw`) and "csv" force a format.
  std::string format = "auto";
  std::vector<int> types;  // particle types to read; empty = all
  std::size_t chunk_particles = std::size_t{1} << 20;
  bool read_velocity = true;
  bool read_id = true;
  bool read_smoothing = true;  // the file's smoothing lengths, where it has them (docs/INPUT_FORMATS.md)
  RawLayout raw;
  CsvOptions csv;
  // The periodic box, where the header's is wrong or missing: >= 0 replaces
  // the header's box size (0 = not periodic; e.g. ICs that leave it 0);
  // negative = the header's. Finite, else OpenSnapshot throws.
  double box_size_override = -1;
  // Treat the particles as not periodic whatever the header says (box_size
  // 0): ingest then indexes their bounding cube. Not with box_size_override.
  bool ignore_box = false;
  // HDF5: have libhdf5 read each snapshot, its structure and its particles,
  // in a reader process of its own, so that libhdf5 crashing, looping or
  // allocating without end on a damaged file ends that process with an
  // error naming the file, not this process (docs/INPUT_FORMATS.md). Off
  // only to fuzz libhdf5 itself in this process, where coverage is measured.
  bool isolate_hdf5 = true;
};

// How far a particle may lie outside a periodic box [0, box_size)^3, as a
// fraction of box_size, and still be taken (ingest wraps it into the box):
// codes write particles that crossed a face since the last wrap. A particle
// further out means the box is wrong, and the read fails (BadInput naming the
// file, the box and the particle) rather than wrap the data into it.
inline constexpr double kPeriodicBoxTolerance = 0.01;

// Where one segment of a snapshot (the particles of one type in one file)
// lies in its file when every column is a plain array in this machine's byte
// order, so that a reader may map the file instead of copying it: 3 floats a
// particle for positions (and velocities), 4- or 8-byte unsigned IDs, and one
// mass for all the segment's particles (a header's mass table).
struct MappableSegment {
  std::size_t file = 0;  // index into SnapshotHeader::files
  int type = 0;
  std::uint64_t count = 0;
  double mass = 0;
  std::uint64_t position_offset = 0;  // byte offset of the first particle's x
  std::uint64_t velocity_offset = 0;  // meaningful when the header has velocities
  std::uint64_t id_offset = 0;        // meaningful when the header has IDs
  std::size_t id_bytes = 0;           // 4 or 8
};

// A rewindable stream of particle batches. Not thread-safe; one source per
// thread. (HDF5 sources also share the non-thread-safe HDF5 library, so
// several HDF5 sources must not be read concurrently.)
class ParticleSource {
 public:
  virtual ~ParticleSource() = default;
  virtual const SnapshotHeader& header() const = 0;
  // Replaces the contents of `chunk` with the next 1 to chunk_particles
  // particles; returns false (and leaves `chunk` empty) at the end.
  virtual bool Next(ParticleChunk& chunk) = 0;
  // Starts again from the first particle.
  virtual void Rewind() = 0;
  // Passes over the batch Next() would hand out next, and returns how many
  // particles it holds (0 at the end). A reader that can seek there does
  // not read it (nor check its values); this default reads it.
  virtual std::uint64_t Skip() {
    ParticleChunk batch;
    return Next(batch) ? batch.size() : 0;
  }
  // The particles Next() hands out, in the same order, as segments a reader
  // may map (MappableSegment), when the format stores every column so; else
  // empty. The values are not checked: a reader of the segments must check
  // what Next() checks (finite positions and velocities) or read through
  // Next() instead. Masses are finite and > 0. A source whose chunks carry
  // smoothing lengths gives none: a segment has no place for them, and a
  // reader of the segments would drop them.
  virtual std::vector<MappableSegment> MappableSegments() const { return {}; }
  // Asks Next() to leave velocities and IDs out of its chunks from now on
  // (true), or to fill them again (false), for a pass that needs only
  // positions, masses, types and smoothing lengths: a format that stores
  // each column apart (GADGET's blocks, HDF5's datasets) then reads a third
  // to a half of the bytes. A request only: a source may fill them anyway.
  virtual void SetPositionsOnly(bool positions_only) { (void)positions_only; }
};

// Asks `source` for positions only (ParticleSource::SetPositionsOnly) while
// it lives.
class PositionsOnlyReads {
 public:
  explicit PositionsOnlyReads(ParticleSource& source) : source_(source) { source_.SetPositionsOnly(true); }
  ~PositionsOnlyReads() { source_.SetPositionsOnly(false); }
  PositionsOnlyReads(const PositionsOnlyReads&) = delete;
  PositionsOnlyReads& operator=(const PositionsOnlyReads&) = delete;

 private:
  ParticleSource& source_;
};

// Reads `source` from its start, handing `consume(batch, first_index)` the
// batches of one reader's share among `every` readers: batches first,
// first + every, first + 2 every, ..., the others skipped
// (ParticleSource::Skip); `first_index` is the index of the batch's first
// particle in the source's order, whoever reads it. `batch` is `chunk`,
// which `consume` may change. Returns the batches passed in all.
template <typename Consume>
std::uint64_t ReadShare(ParticleSource& source, std::uint64_t every, std::uint64_t first, ParticleChunk& chunk,
                        Consume&& consume) {
  source.Rewind();
  std::uint64_t index = 0, batch = 0;
  for (;; ++batch) {
    if (batch % every != first) {
      const std::uint64_t skipped = source.Skip();
      if (skipped == 0) break;
      index += skipped;
      continue;
    }
    if (!source.Next(chunk)) break;
    const std::uint64_t size = chunk.size();
    consume(chunk, index);
    index += size;
  }
  return batch;
}

// Opens a snapshot. `path` is a single file, any one file of a multi-file set
// (snap.1, snap.2.hdf5), or the base name of a set (snap -> snap.0, snap.1, ...
// or snap.0.hdf5, ...).
std::unique_ptr<ParticleSource> OpenSnapshot(const std::string& path, const ReadOptions& options);

}  // namespace octocosm
