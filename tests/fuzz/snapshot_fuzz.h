// Running a snapshot reader to completion on fuzzed bytes (tests/fuzz).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "base/error.h"
#include "index/particle_chunk.h"
#include "tests/fuzz/fuzz_target.h"
#include "ingest/snapshot/snapshot_source.h"

namespace octocosm::fuzz {

// Chunks far smaller than a real run's, so that a small input still crosses
// chunk, segment and file boundaries.
inline constexpr std::size_t kFuzzChunkParticles = 97;

// Opens `path` with `options`, reads every particle, rewinds and reads the
// first chunk again, and asks for the mappable segments. An Error is the
// reader refusing the input; anything else escapes.
inline void ReadSnapshotToCompletion(const std::string& path, ReadOptions options) {
  options.chunk_particles = kFuzzChunkParticles;
  try {
    auto source = OpenSnapshot(path, options);
    ParticleChunk chunk;
    std::uint64_t particles = 0;
    while (source->Next(chunk)) particles += chunk.size();
    Require(particles == source->header().total_count, "the particles handed out differ from the header's count");
    source->Rewind();
    source->Next(chunk);
    (void)source->MappableSegments();
  } catch (const Error& e) {
    Refused(e);
  }
}

// Writes `data` to `name` in the scratch directory and reads it as a snapshot.
inline void ReadSnapshotBytes(const std::uint8_t* data, std::size_t size, const std::string& name,
                              const ReadOptions& options) {
  const std::string path = (ScratchDirectory() / name).string();
  WriteFileBytes(path, {data, size});
  ReadSnapshotToCompletion(path, options);
}

}  // namespace octocosm::fuzz
