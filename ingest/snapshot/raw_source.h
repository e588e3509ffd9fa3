// ParticleSource for raw binary files: fixed-size records, no header, laid
// out as a RawLayout declares (see RawLayout::Parse). The file size must be a
// whole number of records. Particles without a mass column get mass 1 and
// all particles are type 0.
#pragma once

#include <memory>
#include <string>

#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

std::unique_ptr<ParticleSource> OpenRawSnapshot(const std::string& file, const ReadOptions& options);

}  // namespace octocosm
