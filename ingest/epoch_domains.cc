#include "ingest/epoch_domains.h"

#include <algorithm>
#include <string>

#include "base/error.h"

namespace octocosm {

namespace {

// The most levels the grid goes down: 8^6 cells, 2 MiB of counts.
constexpr int kMostGridLevels = 6;

// Points below every node down to the grid: pyramid[l][i] for the i-th
// node of level l in Morton order.
std::vector<std::vector<std::uint64_t>> CountPyramid(std::span<const std::uint64_t> cells, int level) {
  std::vector<std::vector<std::uint64_t>> pyramid(static_cast<std::size_t>(level) + 1);
  pyramid[static_cast<std::size_t>(level)].assign(cells.begin(), cells.end());
  for (int l = level - 1; l >= 0; --l) {
    const std::vector<std::uint64_t>& below = pyramid[static_cast<std::size_t>(l) + 1];
    std::vector<std::uint64_t>& here = pyramid[static_cast<std::size_t>(l)];
    here.assign(below.size() / 8, 0);
    for (std::size_t i = 0; i < below.size(); ++i) here[i / 8] += below[i];
  }
  return pyramid;
}

std::uint64_t IndexAtLevel(NodeKey key) { return key.value() - (std::uint64_t{1} << (3 * key.level())); }

struct Unit {
  NodeKey key;
  std::uint64_t points;
};

// The units below `node` in depth-first order: nodes that are leaves by
// their count, or cells of the grid.
void CollectUnits(NodeKey node, const std::vector<std::vector<std::uint64_t>>& pyramid, int level,
                  std::uint64_t leaf_capacity, std::vector<Unit>& units) {
  const std::uint64_t points = pyramid[static_cast<std::size_t>(node.level())][IndexAtLevel(node)];
  if (points == 0) return;
  if (points <= leaf_capacity || node.level() == level) {
    units.push_back({node, points});
    return;
  }
  for (int octant = 0; octant < 8; ++octant) CollectUnits(node.Child(octant), pyramid, level, leaf_capacity, units);
}

// The domains below `node`, whose units are units[*next, ...): the node
// itself where one rank owns them all, else its children's.
void CollectDomains(NodeKey node, const std::vector<Unit>& units, const std::vector<int>& unit_owner,
                    std::size_t& next, EpochDomains& domains) {
  std::size_t end = next;
  while (end < units.size() && node.IsAncestorOrSelf(units[end].key)) ++end;
  if (end == next) return;
  if (unit_owner[next] == unit_owner[end - 1]) {
    domains.keys.push_back(node);
    domains.owner.push_back(unit_owner[next]);
    next = end;
    return;
  }
  for (int octant = 0; octant < 8 && next < end; ++octant) CollectDomains(node.Child(octant), units, unit_owner, next, domains);
}

}  // namespace

std::uint64_t EpochDomains::CellIndex(const Cube& cube, const double* point, int level) {
  return IndexAtLevel(cube.LeafKey(point, level));
}

std::vector<NodeKey> EpochDomains::DomainsOf(int rank) const {
  std::vector<NodeKey> mine;
  for (std::size_t i = 0; i < keys.size(); ++i) {
    if (owner[i] == rank) mine.push_back(keys[i]);
  }
  return mine;
}

int DomainGridLevel(int max_level) { return std::clamp(max_level, 0, kMostGridLevels); }

EpochDomains ShareDomains(std::span<const std::uint64_t> cell_counts, int level, std::uint64_t leaf_capacity,
                          int ranks) {
  if (ranks < 1) throw Error::InvalidArgument("ShareDomains: no ranks");
  if (level < 0 || level > kMostGridLevels || cell_counts.size() != (std::size_t{1} << (3 * level))) {
    throw Error::InvalidArgument("ShareDomains: " + std::to_string(cell_counts.size()) + " cell counts for level " +
                                 std::to_string(level));
  }
  const auto pyramid = CountPyramid(cell_counts, level);
  std::vector<Unit> units;
  CollectUnits(NodeKey::Root(), pyramid, level, leaf_capacity, units);
  const std::uint64_t total = pyramid[0][0];
  // A unit goes to the rank whose share of the points its middle falls in.
  std::vector<int> unit_owner(units.size());
  std::uint64_t before = 0;
  for (std::size_t u = 0; u < units.size(); ++u) {
    const long double middle = static_cast<long double>(before) + static_cast<long double>(units[u].points) / 2;
    const int owner = static_cast<int>(middle * ranks / static_cast<long double>(total));
    unit_owner[u] = std::min(owner, ranks - 1);
    before += units[u].points;
  }
  EpochDomains domains;
  domains.level = level;
  std::size_t next = 0;
  CollectDomains(NodeKey::Root(), units, unit_owner, next, domains);
  domains.cell_domain.assign(cell_counts.size(), 0);
  for (std::size_t d = 0; d < domains.keys.size(); ++d) {
    const NodeKey key = domains.keys[d];
    const auto [first, last] = key.DescendantRange(level);
    const std::uint64_t base = std::uint64_t{1} << (3 * level);
    for (std::uint64_t v = first; v <= last; ++v) domains.cell_domain[v - base] = static_cast<std::uint32_t>(d);
  }
  return domains;
}

}  // namespace octocosm
