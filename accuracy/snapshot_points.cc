#include "accuracy/snapshot_points.h"

#include "ingest/snapshot/snapshot_source.h"

namespace octocosm::accuracy {

ParticleChunk ReadSnapshotPoints(const std::string& path) {
  ReadOptions options;
  options.read_velocity = false;
  options.read_smoothing = false;
  const auto source = OpenSnapshot(path, options);
  ParticleChunk all, chunk;
  while (source->Next(chunk)) all.Append(chunk);
  return all;
}

}  // namespace octocosm::accuracy
