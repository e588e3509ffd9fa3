// Temporary particle files of the ingest pipeline: chunk files (the points of
// one region) and sorted runs (points ordered by ID). A file is a sequence of
// batches, each a ParticleChunk serialised column by column, so a batch is
// written and read with a few large I/O calls; positions, masses, types and
// IDs are stored as narrow as the batch's values allow (floats, one value,
// 32 bits), exactly.
//
// These files live only for the duration of one ingest, in its temporary
// directory, so the format is private; it still carries a magic number and
// length checks so that a full disk or a stray file is reported rather than
// misread.
#pragma once

#include <array>
#include <cstdint>
#include <cstdio>
#include <string>

#include "index/particle_chunk.h"

namespace octocosm {

// Which optional columns the batches of a file carry (all batches alike).
struct ParticleColumns {
  bool id = false;
  bool smoothing = false;  // ParticleChunk::smoothing
  std::array<bool, kVectorColumnCount> vectors{};  // indexed by VectorColumn

  bool& vector(VectorColumn column) { return vectors[static_cast<std::size_t>(column)]; }
  bool vector(VectorColumn column) const { return vectors[static_cast<std::size_t>(column)]; }
  // Bytes one point takes in memory, and at most in a file: position 24,
  // mass 8, type 1 + options (ID 8, smoothing 4, each vector 12). A file's
  // batch keeps positions as floats, the mass and type once, and IDs in 32
  // bits where all of its values allow.
  std::size_t BytesPerPoint() const;
};

class ParticleFileWriter {
 public:
  ParticleFileWriter(std::string path, ParticleColumns columns);
  ParticleFileWriter(ParticleFileWriter&&) noexcept;
  ParticleFileWriter& operator=(ParticleFileWriter&&) noexcept;
  ParticleFileWriter(const ParticleFileWriter&) = delete;
  ParticleFileWriter& operator=(const ParticleFileWriter&) = delete;
  ~ParticleFileWriter();

  // Appends the points [begin, end) of `chunk` as one batch. The chunk must
  // carry the file's optional columns (extra columns are ignored).
  void Append(const ParticleChunk& chunk, std::size_t begin, std::size_t end);
  void Append(const ParticleChunk& chunk) { Append(chunk, 0, chunk.size()); }
  // Flushes and closes; throws Error::Io (e.g. disk full).
  void Close();

  std::uint64_t point_count() const { return point_count_; }
  const std::string& path() const { return path_; }

 private:
  void Write(const void* data, std::size_t size);
  template <typename Narrow, typename Wide>
  void WriteNarrow(const Wide* values, std::size_t count);

  std::string path_;
  ParticleColumns columns_;
  std::FILE* file_ = nullptr;
  std::uint64_t point_count_ = 0;
};

class ParticleFileReader {
 public:
  explicit ParticleFileReader(std::string path);
  ParticleFileReader(ParticleFileReader&&) noexcept;
  ParticleFileReader& operator=(ParticleFileReader&&) noexcept;
  ParticleFileReader(const ParticleFileReader&) = delete;
  ParticleFileReader& operator=(const ParticleFileReader&) = delete;
  ~ParticleFileReader();

  // Replaces `chunk` with the next batch; false at the end of the file.
  bool Next(ParticleChunk& chunk);
  // Appends every remaining batch to `chunk`.
  void ReadAll(ParticleChunk& chunk);

  const ParticleColumns& columns() const { return columns_; }

 private:
  void Read(void* data, std::size_t size, const char* what);
  template <typename Narrow, typename Wide>
  void ReadNarrow(Wide* values, std::size_t count, const char* what);
  bool ReadBatch(ParticleChunk& chunk, bool append);

  std::string path_;
  ParticleColumns columns_;
  std::FILE* file_ = nullptr;
};

}  // namespace octocosm
