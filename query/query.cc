#include "query/query.h"

#include "base/error.h"

namespace octocosm {
namespace {

template <typename T>
void KeepColumn(std::vector<T>& column, std::size_t stride, const std::vector<std::uint32_t>& keep) {
  if (column.empty()) return;
  std::size_t out = 0;
  for (std::uint32_t i : keep) {
    for (std::size_t c = 0; c < stride; ++c) column[out * stride + c] = column[std::size_t{i} * stride + c];
    ++out;
  }
  column.resize(out * stride);
}

}  // namespace

void KeepPoints(NodePoints& points, const std::vector<std::uint32_t>& keep) {
  KeepColumn(points.position, 3, keep);
  KeepColumn(points.weight, 1, keep);
  KeepColumn(points.smoothing, 1, keep);
  KeepColumn(points.id, 1, keep);
  KeepColumn(points.type, 1, keep);
  for (std::vector<float>* column : VectorColumns(points)) KeepColumn(*column, 3, keep);
  KeepColumn(points.velocity_dispersion, 1, keep);
  KeepColumn(points.shape, 6, keep);
  KeepColumn(points.refine_bound, 3, keep);
  KeepColumn(points.grid, 1, keep);
  points.child_cluster.clear();  // would name points no longer kept
}

std::vector<IndexEntry> SelectNodes(const Dataset& dataset, const Region& region, const QueryOptions& options,
                                    SelectionStats& stats) {
  if (options.level.has_value() == options.screen_error.has_value()) {
    throw Error::InvalidArgument("a query needs exactly one level of detail: a level or a screen-space error");
  }
  if (options.level) return SelectLevel(dataset, options.epoch, region, *options.level, stats);
  return SelectByScreenError(dataset, options.epoch, region, *options.screen_error, stats);
}

namespace {

// The nodes a query reads, counted into its statistics.
std::vector<IndexEntry> SelectAndCount(const Dataset& dataset, const Region& region, const QueryOptions& options,
                                       QueryStats& stats) {
  std::vector<IndexEntry> nodes = SelectNodes(dataset, region, options, stats.selection);
  stats.nodes_selected = nodes.size();
  for (const IndexEntry& entry : nodes) stats.points_selected += entry.point_count;
  return nodes;
}

// Reads kept in flight: several against a server, one locally. (An epoch out
// of range is the selection's error.)
std::size_t ReadsInFlight(const Dataset& dataset, std::uint32_t epoch) {
  return epoch < dataset.epoch_count() && dataset.store().page_file(epoch).remote() ? kRemoteReadsInFlight : 1;
}

}  // namespace

QueryCursor::QueryCursor(const Dataset& dataset, const Region& region, const QueryOptions& options)
    : region_(region),
      blocks_(SelectAndCount(dataset, region, options, stats_),
              ReadsInFlight(dataset, options.epoch),
              [&dataset, epoch = options.epoch,
               wanted = (options.columns & (kAllColumns | kClusterLinkColumns)) |
                        ColumnBit(ColumnId::kPosition)](const IndexEntry& entry) {
                Fetched fetched;
                fetched.block = ReadBlockColumns(dataset, epoch, entry, wanted, fetched.counters);
                return fetched;
              }) {}

bool QueryCursor::Next(QueryBatch& batch) {
  while (std::optional<Fetched> fetched = blocks_.Next()) {
    stats_.reads.blocks += fetched->counters.blocks;
    stats_.reads.reads += fetched->counters.reads;
    stats_.reads.bytes += fetched->counters.bytes;
    DecodedBlock& block = fetched->block;
    const std::uint32_t n = block.header.point_count;
    stats_.points_scanned += n;
    keep_.clear();
    for (std::uint32_t i = 0; i < n; ++i) {
      if (region_.Contains(&block.points.position[3 * std::size_t{i}])) keep_.push_back(i);
    }
    if (keep_.empty()) continue;
    if (keep_.size() != n) KeepPoints(block.points, keep_);
    stats_.points_returned += keep_.size();
    batch.node = block.header.key;
    batch.count = keep_.size();
    batch.points = std::move(block.points);
    return true;
  }
  return false;
}

QueryStats RunQuery(const Dataset& dataset, const Region& region, const QueryOptions& options,
                    const QueryCallback& callback) {
  QueryCursor cursor(dataset, region, options);
  QueryBatch batch;
  while (cursor.Next(batch)) callback(batch);
  return cursor.stats();
}

}  // namespace octocosm
