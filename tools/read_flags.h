// The snapshot-reading flags shared by `octocosm ingest` and
// `octocosm render --reference` (which must read a snapshot exactly as ingest
// did): --format, --types, --box-size, --ignore-box, --raw-layout,
// --no-velocity, --no-ids, --no-snapshot-smoothing, --chunk-particles.
#pragma once

#include <cstddef>
#include <string>

#include "ingest/snapshot/snapshot_source.h"

namespace CLI {
class App;
}

namespace octocosm {

struct ReadFlags {
  std::string format = "auto", raw_layout, types;
  double box_size = -1;  // negative: not given
  bool ignore_box = false;
  bool no_velocity = false, no_ids = false, no_snapshot_smoothing = false;
  std::size_t chunk_particles = std::size_t{1} << 16;
};

void AddReadFlags(CLI::App& command, ReadFlags& flags);
// Throws Error::InvalidArgument naming the flag.
ReadOptions ReadOptionsFrom(const ReadFlags& flags);

}  // namespace octocosm
