#include "tools/reference_render.h"

#include <algorithm>
#include <chrono>
#include <thread>
#include <vector>

#include "index/node_hierarchy.h"
#include "index/sampler.h"
#include "render/reference_rasterizer.h"
#include "storage/error.h"

namespace octocosm {
namespace {

// Splits [0, n) into `parts` contiguous ranges and runs `work(part, begin, end)` on a thread each.
template <typename Work>
void ParallelRanges(std::size_t n, unsigned parts, Work work) {
  std::vector<std::thread> threads;
  for (unsigned p = 1; p < parts; ++p) {
    threads.emplace_back([&, p] { work(p, n * p / parts, n * (p + 1) / parts); });
  }
  work(0, 0, n / parts);
  for (auto& t : threads) t.join();
}

class LeafCells {
 public:
  LeafCells(const Dataset& dataset, std::uint32_t epoch, const std::string& input)
      : hierarchy_(NodeHierarchy::Load(dataset, epoch)),
        cube_(dataset.cube(epoch)),
        bits_(dataset.sampler().density_grid_bits),
        input_(input) {}

  // The key of the particle's fine density cell: leaf index and cell index.
  // The position must be wrapped (Cube::Wrap) as ingest stored it.
  std::uint64_t CellKey(const double* p, std::int32_t* leaf_out = nullptr) const {
    std::int32_t node = 0;
    if (hierarchy_.empty()) Missing(p);
    for (;;) {
      const NodeHierarchy::Node& n = hierarchy_.node(node);
      if (n.is_leaf()) break;
      const std::int32_t child = n.children[static_cast<std::size_t>(cube_.ChildOctant(p, n.key.level()))];
      if (child < 0) Missing(p);
      node = child;
    }
    if (leaf_out) *leaf_out = node;
    return (static_cast<std::uint64_t>(node) << 24) | DensityCellIndex(p, hierarchy_.node(node).key, cube_, bits_);
  }

  double SmoothingLength(std::int32_t leaf, double mass, double cell_mass) const {
    const int level = hierarchy_.node(leaf).key.level();
    return SmoothingLengthFor(mass, cell_mass, cube_.NodeSize(level + bits_), cube_.NodeSize(level));
  }

  const Cube& cube() const { return cube_; }

 private:
  [[noreturn]] void Missing(const double* p) const {
    throw Error::BadInput(input_, "a particle at (" + std::to_string(p[0]) + ", " + std::to_string(p[1]) + ", " +
                                      std::to_string(p[2]) +
                                      ") lies where the store has no node: is this the snapshot the epoch was "
                                      "ingested from, read with the same flags?");
  }

  NodeHierarchy hierarchy_;
  Cube cube_;
  int bits_;
  std::string input_;
};

struct CellMass {
  std::uint64_t key;
  double mass;
};

}  // namespace

std::vector<HdrImage> RenderReference(const Dataset& dataset, std::uint32_t epoch, const std::string& input,
                                      std::span<const RenderView> views, const ReferenceRenderOptions& options,
                                      ReferenceRenderStats* stats) {
  if (views.empty()) return {};
  const auto start = std::chrono::steady_clock::now();
  const unsigned threads = options.threads ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  const LeafCells cells(dataset, epoch, input);
  std::unique_ptr<ParticleSource> source = OpenSnapshot(input, options.read);
  const bool need_velocity = ColorModeNeedsVelocity(options.color);
  if (need_velocity && !source->header().has_velocity) {
    throw Error::InvalidArgument("colour mode '" + std::string(ColorModeName(options.color)) + "' needs velocities, and " +
                                 input + " has none");
  }

  // Pass 1: the mass in every occupied fine cell.
  std::vector<CellMass> pairs;
  ParticleChunk chunk;
  std::uint64_t particles = 0;
  while (source->Next(chunk)) {
    const std::size_t first = pairs.size();
    pairs.resize(first + chunk.size());
    ParallelRanges(chunk.size(), threads, [&](unsigned, std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        double p[3] = {chunk.position[3 * i], chunk.position[3 * i + 1], chunk.position[3 * i + 2]};
        cells.cube().Wrap(p);
        pairs[first + i] = {cells.CellKey(p), chunk.mass[i]};
      }
    });
    particles += chunk.size();
  }
  std::sort(pairs.begin(), pairs.end(), [](const CellMass& a, const CellMass& b) {
    return a.key != b.key ? a.key < b.key : a.mass < b.mass;
  });
  std::vector<std::uint64_t> keys;
  std::vector<double> masses;
  for (std::size_t i = 0; i < pairs.size();) {
    std::size_t j = i;
    double sum = 0;
    while (j < pairs.size() && pairs[j].key == pairs[i].key) sum += pairs[j++].mass;
    keys.push_back(pairs[i].key);
    masses.push_back(sum);
    i = j;
  }
  pairs = {};

  // Pass 2: draw, each thread into its own rasterizer per view.
  std::vector<std::vector<ReferenceRasterizer>> rasterizers(threads);
  for (auto& per_thread : rasterizers) {
    for (const RenderView& view : views) per_thread.emplace_back(view);
  }
  source->Rewind();
  while (source->Next(chunk)) {
    ParallelRanges(chunk.size(), threads, [&](unsigned part, std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        double p[3] = {chunk.position[3 * i], chunk.position[3 * i + 1], chunk.position[3 * i + 2]};
        cells.cube().Wrap(p);
        std::int32_t leaf = 0;
        const std::uint64_t key = cells.CellKey(p, &leaf);
        const double cell_mass = masses[static_cast<std::size_t>(std::lower_bound(keys.begin(), keys.end(), key) - keys.begin())];
        const double h = cells.SmoothingLength(leaf, chunk.mass[i], cell_mass);
        const bool selected = options.selection && chunk.has_id() && options.selection->Contains(chunk.id[i]);
        for (std::size_t v = 0; v < views.size(); ++v) {
          const double a = options.color == ColorMode::kDensity
                               ? 0.0
                               : PointAttribute(options.color, chunk.has_velocity() ? &chunk.velocity[3 * i] : nullptr,
                                                chunk.type[i], views[v]);
          rasterizers[part][v].Add(p, chunk.mass[i], h, a, selected);
        }
      }
    });
  }
  std::vector<HdrImage> images;
  for (std::size_t v = 0; v < views.size(); ++v) {
    for (unsigned t = 1; t < threads; ++t) rasterizers[0][v].Merge(rasterizers[t][v]);
    images.push_back(rasterizers[0][v].image());
  }
  if (stats) {
    stats->particles = particles;
    stats->points_drawn = rasterizers[0][0].points_drawn();
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return images;
}

HdrImage RenderReference(const Dataset& dataset, std::uint32_t epoch, const std::string& input, const RenderView& view,
                         const ReferenceRenderOptions& options, ReferenceRenderStats* stats) {
  return std::move(RenderReference(dataset, epoch, input, std::span<const RenderView>(&view, 1), options, stats)[0]);
}

}  // namespace octocosm
