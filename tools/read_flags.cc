#include "tools/read_flags.h"

#include <cmath>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "tools/cli_util.h"

namespace octocosm {

void AddReadFlags(CLI::App& command, ReadFlags& flags) {
  command.add_option("--box-size", flags.box_size,
                     "periodic box size, instead of the header's (0 = not periodic); particles more than 1% of it "
                     "outside [0, size) are an error");
  command.add_flag("--ignore-box", flags.ignore_box,
                   "treat the particles as not periodic, whatever box the header declares: index their bounding cube");
  command.add_option("--types", flags.types, "particle types to read, e.g. '1,2' (default: all)");
  command.add_option("--format", flags.format, "input format")
      ->check(CLI::IsMember({"auto", "gadget", "hdf5", "raw", "csv"}))
      ->default_val("auto");
  command.add_option("--raw-layout", flags.raw_layout, "record layout of raw binary input, e.g. 'xyz:f32,vel:f32x3,id:u64'");
  command.add_option("--chunk-particles", flags.chunk_particles, "particles read per batch (small batches stay in CPU caches)")
      ->default_val(std::size_t{1} << 16);
  command.add_flag("--no-velocity", flags.no_velocity, "do not read velocities");
  command.add_flag("--no-ids", flags.no_ids, "do not read particle IDs");
  command.add_flag("--no-snapshot-smoothing", flags.no_snapshot_smoothing,
                   "do not read the snapshot's own smoothing lengths (HSML, SmoothingLength): compute every one "
                   "from neighbours");
}

ReadOptions ReadOptionsFrom(const ReadFlags& flags) {
  ReadOptions read;
  read.format = flags.format;
  read.read_velocity = !flags.no_velocity;
  read.read_id = !flags.no_ids;
  read.read_smoothing = !flags.no_snapshot_smoothing;
  read.chunk_particles = flags.chunk_particles;
  if (flags.box_size != -1 && !(std::isfinite(flags.box_size) && flags.box_size >= 0)) {
    throw Error::InvalidArgument("--box-size must be a finite number >= 0 (0 = not periodic)");
  }
  if (flags.ignore_box && flags.box_size >= 0) {
    throw Error::InvalidArgument("--box-size and --ignore-box contradict each other: give one");
  }
  read.box_size_override = flags.box_size;
  read.ignore_box = flags.ignore_box;
  if (!flags.raw_layout.empty()) read.raw = RawLayout::Parse(flags.raw_layout);
  if (!flags.types.empty()) {
    for (double t : ParseNumberList(flags.types, "--types")) read.types.push_back(static_cast<int>(t));
  }
  return read;
}

}  // namespace octocosm
