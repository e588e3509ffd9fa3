#include "ingest/chunker.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <memory>
#include <numeric>
#include <optional>
#include <span>
#include <stdexcept>
#include <unordered_map>

#include "base/error.h"
#include "base/huge_pages.h"
#include "base/parallel_for.h"
#include "index/cells_below.h"

namespace octocosm {
namespace {

// Fewer points per batch than this are placed on one thread: starting another
// would cost more than it saves.
constexpr std::size_t kPointsPerThread = 16384;
// Loops over a whole resident epoch hand their points to the threads in
// pieces of this many (ParallelForDynamic): small enough that a thread held
// up costs the others little, large enough that taking one costs nothing.
constexpr std::size_t kPointsPerPiece = std::size_t{1} << 16;
// A buffered chunk that is split again is fed to the split in batches of
// this many points.
constexpr std::size_t kResplitBatchPoints = std::size_t{1} << 16;

// Points listed by index lie scattered across a resident epoch's columns, so
// each read of one is a cache miss; fetching this many points ahead lets the
// misses overlap instead of queueing one behind another.
constexpr std::size_t kPrefetchDistance = 16;

// Appends the elements `indices` of `from` to `to`, `width` values per point.
// The target is sized once and written through a pointer: a per-point
// vector::insert was a call per point and column.
template <typename T>
void AppendSelected(const std::vector<T>& from, std::span<const std::uint32_t> indices, std::size_t width,
                    std::vector<T>& to) {
  const std::size_t old = to.size();
  to.resize(old + width * indices.size());  // grows geometrically, like push_back
  T* out = to.data() + old;
  const T* in = from.data();
  if (width == 3) {
    for (const std::uint32_t i : indices) {
      out[0] = in[3 * std::size_t{i}];
      out[1] = in[3 * std::size_t{i} + 1];
      out[2] = in[3 * std::size_t{i} + 2];
      out += 3;
    }
  } else {
    for (const std::uint32_t i : indices) *out++ = in[i];
  }
}

// Copies the points `indices` of `from` to the end of `to` (all columns
// `from` carries).
void AppendPoints(const ParticleChunk& from, std::span<const std::uint32_t> indices, ParticleChunk& to) {
  AppendSelected(from.position, indices, 3, to.position);
  AppendSelected(from.mass, indices, 1, to.mass);
  AppendSelected(from.type, indices, 1, to.type);
  if (from.has_id()) AppendSelected(from.id, indices, 1, to.id);
  if (from.has_smoothing()) AppendSelected(from.smoothing, indices, 1, to.smoothing);
  const auto source = VectorColumns(from);
  const auto target = VectorColumns(to);
  for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
    if (!source[v]->empty()) AppendSelected(*source[v], indices, 3, *target[v]);
  }
}

[[noreturn, gnu::cold, gnu::noinline]] void ThrowOutsideRegion(NodeKey root) {
  throw Error::InvalidArgument("chunker: a point lies outside region " + root.Path());
}

// The cell of `cells` that holds `position`; throws when it lies outside
// the node they are below. Runs once or more per point: the throw is kept
// out of line so that this inlines into the loops.
std::uint32_t CellBelow(const CellsBelow& cells, const double* position, NodeKey root) {
  const std::uint64_t cell = cells.Of(position);
  if (cell > UINT32_MAX) ThrowOutsideRegion(root);
  return static_cast<std::uint32_t>(cell);
}

// Listed points ordered by cell: points[begin[c], begin[c + 1]) are the
// points of cell c, in the order they were listed.
struct CellOrder {
  // Not value-initialised: every entry is written by the parallel placing
  // pass, which so also takes the fresh pages' faults on all threads instead
  // of a zeroing pass on one.
  std::unique_ptr<std::uint32_t[]> points;
  std::vector<std::size_t> begin;  // cells + 1 entries
};

// A stable counting sort of `n` listed points into `cells` cells: cell_of(k)
// is the cell of the k-th listed point, point_of(k) what goes into the
// order for it. Each thread counts, then places, one contiguous part of the
// list, and the parts' places are laid out part after part within each
// cell: the result is the same for any thread count. cell_of is called
// twice per point; it must be cheap. `kept`: the order is kept for the rest
// of the epoch's build rather than freed soon.
template <typename CellOf, typename PointOf>
CellOrder OrderByCell(std::size_t n, std::size_t cells, int threads, const CellOf& cell_of, const PointOf& point_of,
                      bool kept = false) {
  const std::size_t parts = n >= kPointsPerThread * static_cast<std::size_t>(threads) ? static_cast<std::size_t>(threads) : 1;
  const auto part_range = [n, parts](std::size_t part) { return std::pair{n * part / parts, n * (part + 1) / parts}; };
  std::vector<std::vector<std::size_t>> next(parts, std::vector<std::size_t>(cells, 0));
  ParallelFor(parts, static_cast<int>(parts), [&](std::size_t part_begin, std::size_t part_end) {
    for (std::size_t part = part_begin; part < part_end; ++part) {
      const auto [begin, end] = part_range(part);
      std::vector<std::size_t>& count = next[part];
      for (std::size_t k = begin; k < end; ++k) ++count[cell_of(k)];
    }
  }, 1);
  CellOrder order;
  order.begin.resize(cells + 1);
  std::size_t placed = 0;
  for (std::size_t c = 0; c < cells; ++c) {
    order.begin[c] = placed;
    for (std::size_t part = 0; part < parts; ++part) {
      const std::size_t count = next[part][c];
      next[part][c] = placed;
      placed += count;
    }
  }
  order.begin[cells] = placed;
  order.points = std::make_unique_for_overwrite<std::uint32_t[]>(n);
  // Memory filled once and kept is cheaper to fault in on small pages
  // (base/huge_pages.h); what is freed soon stays on huge pages, which the
  // build's allocations then reuse (the resident cells too: with them on
  // small pages as well, the split's CPU fell by as much as the build's rose).
  if (kept) PreferSmallPages(order.points.get(), n * sizeof(std::uint32_t));
  ParallelFor(parts, static_cast<int>(parts), [&](std::size_t part_begin, std::size_t part_end) {
    for (std::size_t part = part_begin; part < part_end; ++part) {
      const auto [begin, end] = part_range(part);
      std::vector<std::size_t>& place = next[part];
      for (std::size_t k = begin; k < end; ++k) order.points[place[cell_of(k)]++] = point_of(k);
    }
  }, 1);
  return order;
}

// The points of `batch` sorted into the `cells` cells of `level` below
// `root`: then calls take(c, picks) for every cell c with points, on the
// one thread that handles that cell; `picks` lists the cell's points in
// input order, as positions in `batch`. Cells go to the threads in
// contiguous groups of about equal point counts.
template <typename Take>
void BucketByCell(const Cube& cube, const ParticleChunk& batch, NodeKey root, int level, int threads, Take&& take) {
  const std::size_t n = batch.size();
  if (n > UINT32_MAX) throw Error::InvalidArgument("chunker: more than 2^32 - 1 points in one pass");
  const std::size_t cells = std::size_t{1} << (3 * (level - root.level()));
  const CellsBelow below(cube, root, level);
  std::vector<std::uint32_t> cell_of(n);
  ParallelFor(n, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) cell_of[i] = CellBelow(below, &batch.position[3 * i], root);
  }, kPointsPerThread);
  const CellOrder order = OrderByCell(n, cells, threads, [&cell_of](std::size_t k) { return cell_of[k]; },
                                      [](std::size_t k) { return static_cast<std::uint32_t>(k); });
  std::vector<std::size_t> group_begin = {0};
  for (std::size_t c = 0; c < cells; ++c) {
    const std::size_t group = group_begin.size();
    if (group < static_cast<std::size_t>(threads) && order.begin[c + 1] * threads >= n * group) group_begin.push_back(c + 1);
  }
  while (group_begin.size() <= static_cast<std::size_t>(threads)) group_begin.push_back(cells);
  ParallelFor(static_cast<std::size_t>(threads), n >= kPointsPerThread ? threads : 1,
              [&](std::size_t group_first, std::size_t group_last) {
                for (std::size_t c = group_begin[group_first]; c < group_begin[group_last]; ++c) {
                  const std::span<const std::uint32_t> picks(order.points.get() + order.begin[c],
                                                             order.begin[c + 1] - order.begin[c]);
                  if (!picks.empty()) take(c, picks);
                }
              },
              1);
}

}  // namespace

ParticleChunk Chunk::TakePoints() {
  if (path.empty()) return std::move(points);
  ParticleChunk all = std::move(points);  // a remainder that never spilled, if any
  ParticleChunk from_file;
  {
    ParticleFileReader reader(path);
    reader.ReadAll(from_file);
  }
  std::remove(path.c_str());
  path.clear();
  if (all.size() == 0) return from_file;
  from_file.Append(all);
  return from_file;
}

int SplitLevelsFor(std::uint64_t points, std::uint64_t target_points) {
  int levels = 1;
  double cells = 8;
  while (levels < 6 && static_cast<double>(points) > cells * static_cast<double>(std::max<std::uint64_t>(target_points, 1))) {
    ++levels;
    cells *= 8;
  }
  return levels;
}

Chunker::Chunker(const Cube& cube, ChunkerOptions options) : cube_(cube), options_(std::move(options)) {
  cube_.Validate();
  if (options_.split_levels < 1 || options_.split_levels > 6) {
    throw Error::InvalidArgument("chunker split_levels must be 1..6, got " + std::to_string(options_.split_levels));
  }
  if (options_.max_chunk_points == 0) throw Error::InvalidArgument("chunker max_chunk_points must be positive");
  if (options_.max_level < 0 || options_.max_level > kMaxLevel) {
    throw Error::InvalidArgument("depth limit must be 0.." + std::to_string(kMaxLevel));
  }
}

std::string Chunker::NewChunkPath() {
  char name[40];
  std::snprintf(name, sizeof name, "/chunk-%06llu.pts", static_cast<unsigned long long>(next_file_++));
  return options_.temp_dir + name;
}

std::vector<Chunk> Chunker::Distribute(NodeKey root, int levels, const PointPass& pass) {
  const int level = root.level() + levels;
  const std::uint64_t first = root.DescendantRange(level).first;
  const std::size_t cells = std::size_t{1} << (3 * levels);
  const int threads = std::max(options_.threads, 1);
  std::vector<Chunk> chunks(cells);
  std::vector<std::optional<ParticleFileWriter>> writers(cells);  // opened on a chunk's first spill
  // What the buffers of earlier splits hold is not free for this one's
  // (SplitAt spills them down to half the budget, so at least that is).
  const std::size_t budget = BufferedPointBudget();
  const std::size_t max_buffered = std::max<std::size_t>(budget - std::min<std::size_t>(held_points_, budget / 2), 1);
  std::size_t buffered_points = 0;

  // Appends the buffers of chunks `spilling` to their files, on all threads
  // (each file is written by one), and gives their memory back.
  auto spill = [&](const std::vector<std::size_t>& spilling) {
    for (std::size_t c : spilling) {
      if (chunks[c].path.empty()) {
        chunks[c].path = NewChunkPath();
        writers[c].emplace(chunks[c].path, options_.columns);
      }
      spilled_points_ += chunks[c].points.size();
      buffered_points -= chunks[c].points.size();
    }
    // Largest first, dealt round-robin: the threads write about as much.
    const std::size_t parts = static_cast<std::size_t>(threads);
    ParallelFor(parts, threads, [&](std::size_t part_begin, std::size_t part_end) {
      for (std::size_t part = part_begin; part < part_end; ++part) {
        for (std::size_t k = part; k < spilling.size(); k += parts) {
          Chunk& chunk = chunks[spilling[k]];
          writers[spilling[k]]->Append(chunk.points);
          chunk.points = ParticleChunk();  // give the memory back
        }
      }
    }, 1);
  };

  pass([&](const ParticleChunk& batch) {
    BucketByCell(cube_, batch, root, level, threads, [&](std::size_t c, std::span<const std::uint32_t> picks) {
      AppendPoints(batch, picks, chunks[c].points);
      chunks[c].point_count += picks.size();
    });
    buffered_points += batch.size();
    peak_buffered_points_ = std::max<std::uint64_t>(peak_buffered_points_, held_points_ + buffered_points);
    if (buffered_points > max_buffered) {
      // Spill the fullest buffers first: the most memory back per write call.
      std::vector<std::size_t> order(cells);
      std::iota(order.begin(), order.end(), 0);
      std::sort(order.begin(), order.end(),
                [&](std::size_t a, std::size_t b) { return chunks[a].points.size() > chunks[b].points.size(); });
      std::vector<std::size_t> spilling;
      std::size_t left = buffered_points;
      for (std::size_t c : order) {
        if (left <= max_buffered / 2 || chunks[c].points.size() == 0) break;
        left -= chunks[c].points.size();
        spilling.push_back(c);
      }
      spill(spilling);
    }
  });

  // A chunk that spilled once goes wholly to its file.
  std::vector<std::size_t> spilled;
  for (std::size_t c = 0; c < cells; ++c) {
    if (!chunks[c].path.empty() && chunks[c].points.size() > 0) spilled.push_back(c);
  }
  std::sort(spilled.begin(), spilled.end(),
            [&](std::size_t a, std::size_t b) { return chunks[a].points.size() > chunks[b].points.size(); });
  spill(spilled);
  std::vector<Chunk> result;
  for (std::size_t c = 0; c < cells; ++c) {
    if (chunks[c].point_count == 0) continue;
    if (writers[c]) writers[c]->Close();
    chunks[c].key = NodeKey::FromValue(first + c);
    held_points_ += chunks[c].points.size();
    result.push_back(std::move(chunks[c]));
  }
  return result;
}

std::size_t Chunker::BufferedPointBudget() const {
  return std::max<std::size_t>(options_.memory_bytes / options_.columns.BytesPerPoint(), 1);
}

void Chunker::SpillHeld(std::vector<Chunk>& chunks, std::uint64_t target) {
  std::vector<Chunk*> buffered;
  for (Chunk& chunk : chunks) {
    if (chunk.points.size() > 0) buffered.push_back(&chunk);
  }
  std::sort(buffered.begin(), buffered.end(),
            [](const Chunk* a, const Chunk* b) { return a->points.size() > b->points.size(); });
  for (Chunk* chunk : buffered) {
    if (held_points_ <= target) break;
    chunk->path = NewChunkPath();
    ParticleFileWriter writer(chunk->path, options_.columns);
    writer.Append(chunk->points);
    writer.Close();
    spilled_points_ += chunk->points.size();
    held_points_ -= chunk->points.size();
    chunk->points = ParticleChunk();  // give the memory back
  }
}

int Chunker::ResplitLevels(std::uint64_t points) const {
  return std::clamp(SplitLevelsFor(points, options_.max_chunk_points / 2), 1, 3);
}

bool Chunker::Oversized(const Chunk& chunk) const {
  return chunk.point_count > options_.max_chunk_points && chunk.key.level() < options_.max_level;
}

// Each resident point's cell at `level`, as a Morton code relative to the
// region being split: computed from the positions once, so that every split
// of the resident points, at any level down to `level`, reads a point's cell
// as a prefix of it (a shift) instead of from its position (three divisions
// and a read of a scattered position per point and split).
//
// The codes are 16 bits wide (five levels) where the first cut and two
// levels of re-splits below it fit in five levels, as they do up to some
// 10^8 points; else 32 bits (ten levels). The array is the split's largest
// fresh memory, whose pages the dense ID table reuses once it is freed:
// halving both lowered a 10^8-point ingest's peak RSS by 190 MiB and its
// system time by a fifth when it ran after a pause. A cut below the codes'
// level is made from the positions.
struct Chunker::ResidentCells {
  static constexpr int kNarrowLevels = 5;
  static constexpr int kWideLevels = 10;
  int level = 0;
  // Per resident point, one of the two; not value-initialised, as CellOrder::points.
  std::unique_ptr<std::uint16_t[]> narrow;
  std::unique_ptr<std::uint32_t[]> wide;

  // f(cells), with cells the array in use (a pointer to its element type).
  template <typename F>
  decltype(auto) Visit(F&& f) const {
    if (narrow) return f(narrow.get());
    return f(wide.get());
  }
};

std::vector<Chunk> Chunker::SplitResident(NodeKey root, const ResidentEpoch& resident) {
  if (resident.size() > UINT32_MAX) {
    throw Error::InvalidArgument("chunker: " + std::to_string(resident.size()) +
                                 " points are more than one resident split takes (2^32 - 1)");
  }
  ResidentCells cells;
  const bool narrow = options_.split_levels + 2 <= ResidentCells::kNarrowLevels;
  const int levels = narrow ? ResidentCells::kNarrowLevels : ResidentCells::kWideLevels;
  cells.level = std::max(std::min(root.level() + levels, options_.max_level), root.level());
  if (narrow) {
    cells.narrow = std::make_unique_for_overwrite<std::uint16_t[]>(resident.size());
  } else {
    cells.wide = std::make_unique_for_overwrite<std::uint32_t[]>(resident.size());
  }
  const CellsBelow below(cube_, root, cells.level);
  cells.Visit([&](auto* cell) {
    using Code = std::remove_pointer_t<decltype(cell)>;
    ParallelForDynamic(resident.size(), std::max(options_.threads, 1), kPointsPerPiece,
                       [&](std::size_t begin, std::size_t end) {
                         resident.ForEachPosition(begin, end, [&](std::size_t i, const double* position) {
                           cell[i] = static_cast<Code>(CellBelow(below, position, root));
                         });
                       });
  });
  std::vector<Chunk> chunks = SplitResidentAt(root, options_.split_levels, resident, cells, {}, nullptr);
  cells = ResidentCells();
  if (options_.leaf_capacity != 0) chunks = MergeLeafSubtrees(root, std::move(chunks));
  return chunks;
}

// The points listed in `subset` (all resident points when it is empty) cut
// into chunks. The top call's order of the points by cell becomes the list
// the chunks share; a call for a chunk that is split again (subset is that
// chunk's stretch of `lists`) writes its finer order back over the stretch.
// So every chunk lists its points as a stretch of one array, in depth-first
// order, with no copies.
std::vector<Chunk> Chunker::SplitResidentAt(NodeKey root, int levels, const ResidentEpoch& resident,
                                            const ResidentCells& cells, std::span<std::uint32_t> subset,
                                            const std::shared_ptr<std::uint32_t[]>& lists) {
  levels = std::max(std::min(levels, options_.max_level - root.level()), 0);
  const int level = root.level() + levels;
  const std::uint64_t first = root.DescendantRange(level).first;
  const std::size_t cell_count = std::size_t{1} << (3 * levels);
  const int threads = std::max(options_.threads, 1);
  const std::size_t n = subset.empty() ? resident.size() : subset.size();
  const auto point_of = [subset](std::size_t k) { return subset.empty() ? static_cast<std::uint32_t>(k) : subset[k]; };
  CellOrder order;
  if (level <= cells.level) {
    // The cell is a prefix of the point's finer one.
    const int shift = 3 * (cells.level - level);
    const std::uint32_t mask = static_cast<std::uint32_t>(cell_count - 1);
    order = cells.Visit([&](const auto* cell) {
      return OrderByCell(n, cell_count, threads, [&](std::size_t k) {
        if (!subset.empty() && k + kPrefetchDistance < n) __builtin_prefetch(cell + subset[k + kPrefetchDistance]);
        return (std::uint32_t{cell[point_of(k)]} >> shift) & mask;
      }, point_of, subset.empty());
    });
  } else {
    // Deeper than the cells computed once (a dense clump): from the positions.
    const CellsBelow below(cube_, root, level);
    std::vector<std::uint32_t> cell_of(n);
    ParallelForDynamic(n, threads, kPointsPerPiece, [&](std::size_t begin, std::size_t end) {
      for (std::size_t k = begin; k < end; ++k) {
        if (k + kPrefetchDistance < end) __builtin_prefetch(resident.PositionAddress(point_of(k + kPrefetchDistance)));
        cell_of[k] = CellBelow(below, resident.Position(point_of(k)).data(), root);
      }
    });
    order = OrderByCell(n, cell_count, threads, [&cell_of](std::size_t k) { return cell_of[k]; }, point_of,
                        subset.empty());
  }
  std::shared_ptr<std::uint32_t[]> own_lists = lists;
  std::span<std::uint32_t> listed = subset;
  if (subset.empty()) {
    own_lists = std::move(order.points);
    listed = std::span<std::uint32_t>(own_lists.get(), n);
  } else {
    std::copy(order.points.get(), order.points.get() + n, subset.begin());
    order.points.reset();
  }
  std::vector<Chunk> result;
  for (std::size_t c = 0; c < cell_count; ++c) {
    const std::span<std::uint32_t> points = listed.subspan(order.begin[c], order.begin[c + 1] - order.begin[c]);
    if (points.empty()) continue;
    Chunk chunk;
    chunk.key = NodeKey::FromValue(first + c);
    chunk.point_count = points.size();
    if (!Oversized(chunk)) {
      chunk.resident = points;
      chunk.resident_lists = own_lists;
      result.push_back(std::move(chunk));
      continue;
    }
    for (Chunk& part : SplitResidentAt(chunk.key, ResplitLevels(chunk.point_count), resident, cells, points, own_lists)) {
      result.push_back(std::move(part));
    }
  }
  return result;
}

std::vector<Chunk> Chunker::SplitTail(std::vector<Chunk> chunks, const ResidentEpoch& resident, std::size_t window,
                                     std::uint64_t most_points) {
  const ResidentCells none;  // level 0: every cut below it is made from the positions
  for (;;) {
    std::size_t largest = chunks.size();
    for (std::size_t c = chunks.size() - std::min(window, chunks.size()); c < chunks.size(); ++c) {
      const Chunk& chunk = chunks[c];
      const bool inner = chunk.point_count > options_.leaf_capacity && chunk.key.level() < options_.max_level;
      if (chunk.resident.empty() || !inner || chunk.point_count <= most_points) continue;
      if (largest == chunks.size() || chunk.point_count > chunks[largest].point_count) largest = c;
    }
    if (largest == chunks.size()) return chunks;
    const Chunk& split = chunks[largest];
    // The chunk's stretch of the shared list, which the cut reorders in
    // place: SplitResidentAt made that list, writable, and hands it out as
    // const only to the chunks' users.
    const auto lists = std::const_pointer_cast<std::uint32_t[]>(split.resident_lists);
    const std::span<std::uint32_t> stretch(lists.get() + (split.resident.data() - lists.get()), split.resident.size());
    std::vector<Chunk> parts = SplitResidentAt(split.key, 1, resident, none, stretch, lists);
    chunks.erase(chunks.begin() + static_cast<std::ptrdiff_t>(largest));
    chunks.insert(chunks.begin() + static_cast<std::ptrdiff_t>(largest), std::make_move_iterator(parts.begin()),
                  std::make_move_iterator(parts.end()));
  }
}

std::vector<Chunk> Chunker::Split(NodeKey root, const PointPass& pass) {
  held_points_ = 0;
  peak_buffered_points_ = 0;
  std::vector<Chunk> chunks = SplitAt(root, options_.split_levels, pass);
  if (options_.leaf_capacity == 0) return chunks;
  return MergeLeafSubtrees(root, std::move(chunks));
}

namespace {

// Makes `merged` list the resident points of `chunks` (non-empty, following
// each other): SplitResidentAt lays their lists out one after the other in
// the array they share, so the join is a longer view of it.
void JoinResident(const std::vector<const Chunk*>& chunks, Chunk& merged) {
  std::size_t total = chunks.front()->resident.size();
  for (std::size_t j = 1; j < chunks.size(); ++j) {
    const Chunk& before = *chunks[j - 1];
    if (before.resident_lists != chunks[j]->resident_lists ||
        before.resident.data() + before.resident.size() != chunks[j]->resident.data()) {
      throw std::logic_error("chunker: the lists of resident chunks " + before.key.Path() + " and " +
                             chunks[j]->key.Path() + " do not follow each other");
    }
    total += chunks[j]->resident.size();
  }
  merged.resident = {chunks.front()->resident.data(), total};
  merged.resident_lists = chunks.front()->resident_lists;
}

}  // namespace

std::vector<Chunk> Chunker::MergeLeafSubtrees(NodeKey root, std::vector<Chunk> chunks) {
  // Points under every node between the region and the chunks.
  std::unordered_map<std::uint64_t, std::uint64_t> below;
  for (const Chunk& chunk : chunks) {
    for (int level = root.level(); level < chunk.key.level(); ++level) {
      below[chunk.key.AncestorAt(level).value()] += chunk.point_count;
    }
  }
  std::vector<Chunk> result;
  for (std::size_t i = 0; i < chunks.size();) {
    // The highest node above this chunk that the tree makes a leaf, if any.
    NodeKey leaf;
    for (int level = root.level(); level < chunks[i].key.level(); ++level) {
      const NodeKey ancestor = chunks[i].key.AncestorAt(level);
      if (below.at(ancestor.value()) <= options_.leaf_capacity) {
        leaf = ancestor;
        break;
      }
    }
    if (leaf == NodeKey()) {
      result.push_back(std::move(chunks[i++]));
      continue;
    }
    // Its chunks follow each other: they come in depth-first order.
    Chunk merged;
    merged.key = leaf;
    bool spilled = false;
    std::vector<const Chunk*> resident;
    for (; i < chunks.size() && leaf.IsAncestorOrSelf(chunks[i].key); ++i) {
      spilled |= !chunks[i].path.empty();
      merged.point_count += chunks[i].point_count;
      if (!chunks[i].resident.empty()) {
        resident.push_back(&chunks[i]);
      } else {
        merged.points.Append(chunks[i].TakePoints());
      }
    }
    if (!resident.empty()) JoinResident(resident, merged);
    if (spilled) {  // back to a file: memory was short when its parts spilled
      merged.path = NewChunkPath();
      ParticleFileWriter writer(merged.path, options_.columns);
      writer.Append(merged.points);
      writer.Close();
      merged.points = ParticleChunk();
    }
    result.push_back(std::move(merged));
  }
  return result;
}

std::vector<Chunk> Chunker::SplitAt(NodeKey root, int levels, const PointPass& pass) {
  levels = std::min(levels, options_.max_level - root.level());
  std::vector<Chunk> result;
  std::vector<Chunk> distributed = Distribute(root, std::max(levels, 0), pass);
  // Chunks kept in memory stay there until the ingest builds them: spill
  // enough that the splits still to come have room within the budget.
  if (held_points_ > BufferedPointBudget() / 2) SpillHeld(distributed, BufferedPointBudget() / 2);
  for (Chunk& chunk : distributed) {
    if (!Oversized(chunk)) {
      result.push_back(std::move(chunk));
      continue;
    }
    // Split the oversized chunk again, streaming its own file (or buffer).
    PointPass own_pass = [&chunk](const std::function<void(const ParticleChunk&)>& consume) {
      if (chunk.path.empty()) {
        // In slices, as a file is read: the split copies a batch into its
        // buffers before it spills.
        std::vector<std::uint32_t> slice;
        for (std::size_t begin = 0; begin < chunk.points.size(); begin += kResplitBatchPoints) {
          const std::size_t end = std::min(chunk.points.size(), begin + kResplitBatchPoints);
          slice.resize(end - begin);
          std::iota(slice.begin(), slice.end(), static_cast<std::uint32_t>(begin));
          ParticleChunk batch;
          AppendPoints(chunk.points, slice, batch);
          consume(batch);
        }
        return;
      }
      ParticleFileReader reader(chunk.path);
      ParticleChunk batch;
      while (reader.Next(batch)) consume(batch);
    };
    std::vector<Chunk> parts = SplitAt(chunk.key, ResplitLevels(chunk.point_count), own_pass);
    if (!chunk.path.empty()) std::remove(chunk.path.c_str());
    held_points_ -= chunk.points.size();
    chunk.points = ParticleChunk();  // its parts hold its points now
    for (Chunk& part : parts) result.push_back(std::move(part));
  }
  return result;
}

}  // namespace octocosm
