// ParticleSource for CSV text: a header row naming the columns (x, y, z
// required; vx, vy, vz, mass, id optional; others ignored), then one particle
// per line, separated by commas or by whitespace. Blank lines and lines
// starting with '#' are skipped. The file is parsed once at open (to count
// and validate the rows) and then streamed line by line; errors name the line.
#pragma once

#include <memory>
#include <string>

#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

std::unique_ptr<ParticleSource> OpenCsvSnapshot(const std::string& file, const ReadOptions& options);

}  // namespace octocosm
