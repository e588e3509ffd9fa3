// A clustered snapshot generated and ingested for the GL tests, and the two
// views they draw it from.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "index/dataset.h"
#include "ingest/ingest.h"
#include "render/render_view.h"
#include "synth/scale_generator.h"
#include "tests/support/temp_dir.h"
#include "tools/camera_flags.h"

namespace octocosm::testing_support {

struct RenderScene {
  explicit RenderScene(const std::string& name) : dir(name) {}
  TempDir dir;
  std::string snapshot, store;
  std::uint64_t particles = 0;
};

// `particles` clustered points in a box of 20 Mpc/h (`octocosm synth scale`,
// in `files` files), ingested with nodes of `capacity` points.
inline RenderScene* MakeRenderScene(const std::string& name, std::uint64_t particles, int files, std::uint64_t seed,
                                    std::size_t capacity) {
  auto* scene = new RenderScene(name);
  synth::ScaleOptions s;
  s.output_directory = (scene->dir.path() / "snap").string();
  s.particle_count = particles;
  s.box_size_mpc_h = 20;
  s.files = files;
  s.seed = seed;
  s.threads = 2;
  const synth::ScaleResult generated = synth::RunScaleGenerator(s);
  scene->particles = generated.particle_count;
  scene->snapshot = (std::filesystem::path(s.output_directory) / s.snapshot_prefix).string();
  IngestOptions o;
  o.inputs = {scene->snapshot};
  o.output = (scene->dir.path() / "store").string();
  o.tree.capacity = capacity;
  o.page_size = 16384;
  o.quiet = true;
  Ingest(o);
  scene->store = o.output;
  return scene;
}

// Outside the box, all of it in view.
inline RenderView OverviewOf(const Dataset& d, int width = 320, int height = 180) {
  Camera c;
  c.position = OverviewPosition(d.cube(0), 60);
  c.look_at = {d.cube(0).size / 2, d.cube(0).size / 2, d.cube(0).size / 2};
  c.near = 1;
  c.far = 1e6;
  return RenderView(c, width, height);
}

// Inside the box, looking at part of it.
inline RenderView InsideOf(const Dataset& d, int width = 320, int height = 180) {
  const double L = d.cube(0).size;
  Camera c;
  c.position = {0.3 * L, 0.45 * L, 0.5 * L};
  c.look_at = {0.8 * L, 0.6 * L, 0.3 * L};
  c.near = 1;
  c.far = 2 * L;
  c.fov_y_degrees = 50;
  return RenderView(c, width, height);
}

}  // namespace octocosm::testing_support
