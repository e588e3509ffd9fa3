#include "query/node_selection.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <string>

#include "base/error.h"

namespace octocosm {
namespace {

void CheckEpoch(const Dataset& dataset, std::uint32_t epoch) {
  if (epoch >= dataset.epoch_count()) {
    throw Error::InvalidArgument("epoch " + std::to_string(epoch) + " is out of range: the store has " +
                                 std::to_string(dataset.epoch_count()) + " epoch(s)");
  }
}

// Depth-first walk from the root. `refine(entry)` says whether a node that
// meets the region should be replaced by its children; a node without
// children is selected whatever `refine` says.
std::vector<IndexEntry> Walk(const Dataset& dataset, std::uint32_t epoch, const Region& region,
                             const std::function<bool(const IndexEntry&)>& refine, SelectionStats& stats) {
  const StoreReader& store = dataset.store();
  const Cube& cube = dataset.cube(epoch);
  const ReaderStats before = store.page_file(epoch).stats();
  std::vector<IndexEntry> selected;
  std::vector<IndexEntry> stack;
  if (auto root = store.Lookup({epoch, NodeKey::Root().value()})) stack.push_back(*root);
  std::vector<IndexEntry> children;
  while (!stack.empty()) {
    const IndexEntry entry = stack.back();
    stack.pop_back();
    ++stats.nodes_visited;
    const NodeKey key = NodeKey::FromValue(entry.key);
    if (!region.MayIntersect(cube.NodeCubeOf(key))) continue;
    children.clear();
    if (key.level() < kMaxLevel && refine(entry)) {
      const KeyRange range = key.DescendantRange(key.level() + 1);
      ++stats.index_scans;
      store.Scan(epoch, range.first, range.last, [&](const IndexEntry& child) {
        children.push_back(child);
        return true;
      });
    }
    if (children.empty()) {
      selected.push_back(entry);
    } else {
      stack.insert(stack.end(), children.rbegin(), children.rend());
    }
  }
  const ReaderStats after = store.page_file(epoch).stats();
  stats.index_pages_read += after.index_page_reads - before.index_page_reads;
  stats.index_bytes_read += after.bytes_read - before.bytes_read;
  std::sort(selected.begin(), selected.end(),
            [](const IndexEntry& a, const IndexEntry& b) { return a.first_page < b.first_page; });
  return selected;
}

}  // namespace

std::vector<IndexEntry> SelectLevel(const Dataset& dataset, std::uint32_t epoch, const Region& region, int level,
                                    SelectionStats& stats) {
  CheckEpoch(dataset, epoch);
  if (level < 0 || level > kMaxLevel) {
    throw Error::InvalidArgument("level " + std::to_string(level) + " is out of range [0, " + std::to_string(kMaxLevel) + "]");
  }
  return Walk(
      dataset, epoch, region, [level](const IndexEntry& entry) { return NodeKey::FromValue(entry.key).level() < level; },
      stats);
}

ScreenErrorMeter::ScreenErrorMeter(const ScreenErrorView& view)
    : position_(view.camera.position),
      near_(view.camera.near),
      pixels_per_unit_at_unit_distance_(view.viewport_height /
                                        (2 * std::tan(view.camera.fov_y_degrees * std::numbers::pi / 360))) {}

double ScreenErrorMeter::operator()(const NodeCube& node, std::uint64_t points) const {
  double distance2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double d = std::max({node.origin[a] - position_[a], 0.0, position_[a] - (node.origin[a] + node.size)});
    distance2 += d * d;
  }
  const double distance = std::max(std::sqrt(distance2), near_);
  const double spacing = node.size / std::cbrt(static_cast<double>(std::max<std::uint64_t>(points, 1)));
  return spacing / distance * pixels_per_unit_at_unit_distance_;
}

double ScreenSpaceError(const NodeCube& node, std::uint64_t points, const ScreenErrorView& view) {
  return ScreenErrorMeter(view)(node, points);
}

std::vector<IndexEntry> SelectByScreenError(const Dataset& dataset, std::uint32_t epoch, const Region& region,
                                            const ScreenErrorView& view, SelectionStats& stats) {
  CheckEpoch(dataset, epoch);
  view.camera.Validate();
  if (!(view.viewport_height > 0) || !std::isfinite(view.viewport_height)) {
    throw Error::InvalidArgument("viewport height must be > 0 pixels");
  }
  if (!(view.threshold_pixels > 0) || !std::isfinite(view.threshold_pixels)) {
    throw Error::InvalidArgument("screen-space error threshold must be > 0 pixels");
  }
  const Cube& cube = dataset.cube(epoch);
  return Walk(
      dataset, epoch, region,
      [&](const IndexEntry& entry) {
        return ScreenSpaceError(cube.NodeCubeOf(NodeKey::FromValue(entry.key)), entry.point_count, view) >
               view.threshold_pixels;
      },
      stats);
}

}  // namespace octocosm
