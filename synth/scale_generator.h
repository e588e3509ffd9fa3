// `octocosm synth scale`: draws the cosmic web once, then has worker threads
// take whole files in turn, each generating its file chunk by chunk
// (ScaleSampler) and streaming the chunks through a GadgetFileWriter. Memory
// is O(halos + nodes + threads * chunk), whatever the particle count. The
// files appear under their final names only once all of them are complete.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "synth/scale_options.h"

namespace octocosm::synth {

// Reported after each file is written (from worker threads, one at a time).
struct ScaleProgress {
  int file = 0;                // the file just finished
  int files_done = 0;
  int file_count = 0;
  std::uint64_t particles_done = 0;  // in finished files
  std::uint64_t particle_count = 0;
  double elapsed_seconds = 0.0;
  std::string path;            // final name of the file
};

struct ScaleResult {
  std::vector<std::string> files;  // in order
  std::uint64_t particle_count = 0;
  double particle_mass = 0.0;      // 1e10 Msun/h
  std::size_t halos = 0;
  std::size_t filaments = 0;
  int threads = 0;                 // worker threads used
  double web_seconds = 0.0;        // drawing the cosmic web
  double total_seconds = 0.0;
};

// Validates the options (Error::InvalidArgument), creates the output
// directory, and writes the snapshot. I/O failures throw Error::Io naming the
// file; no partial snapshot is left under the final names.
ScaleResult RunScaleGenerator(const ScaleOptions& options,
                              const std::function<void(const ScaleProgress&)>& progress = {});

}  // namespace octocosm::synth
