#include "accuracy/snapshot_points.h"

#include "ingest/snapshot/snapshot_source.h"

namespace octocosm::accuracy {

ParticleChunk ReadSnapshotPoints(const std::string& path) {
  ReadOptions options;
  options.read_velocity = false;
  const auto source = OpenSnapshot(path, options);
  ParticleChunk all, chunk;
  while (source->Next(chunk)) {
    all.position.insert(all.position.end(), chunk.position.begin(), chunk.position.end());
    all.mass.insert(all.mass.end(), chunk.mass.begin(), chunk.mass.end());
    all.id.insert(all.id.end(), chunk.id.begin(), chunk.id.end());
    all.type.insert(all.type.end(), chunk.type.begin(), chunk.type.end());
  }
  return all;
}

}  // namespace octocosm::accuracy
