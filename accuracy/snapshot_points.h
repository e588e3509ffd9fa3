// A whole snapshot in memory, for cross-checks on real data: every particle's
// position, mass, ID and type, in the order the readers return them.
#pragma once

#include <string>

#include "index/particle_chunk.h"

namespace octocosm::accuracy {

// Reads every particle of `path` (any format OpenSnapshot detects; velocities
// and smoothing lengths are skipped). Throws as the readers do (Error::BadInput naming the file).
ParticleChunk ReadSnapshotPoints(const std::string& path);

}  // namespace octocosm::accuracy
