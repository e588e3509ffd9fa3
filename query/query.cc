#include "query/query.h"

#include "base/error.h"

namespace octocosm {
namespace {

// Block reads a cursor keeps in flight against a store on a server.
constexpr std::size_t kReadsAhead = 16;

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
  KeepColumn(points.grid, 1, keep);
}

std::vector<IndexEntry> SelectNodes(const Dataset& dataset, const Region& region, const QueryOptions& options,
                                    SelectionStats& stats) {
  if (options.level.has_value() == options.screen_error.has_value()) {
    throw Error::InvalidArgument("a query needs exactly one level of detail: a level or a screen-space error");
  }
  if (options.level) return SelectLevel(dataset, options.epoch, region, *options.level, stats);
  return SelectByScreenError(dataset, options.epoch, region, *options.screen_error, stats);
}

QueryCursor::QueryCursor(const Dataset& dataset, const Region& region, const QueryOptions& options)
    : dataset_(dataset),
      region_(region),
      epoch_(options.epoch),
      wanted_((options.columns & kAllColumns) | ColumnBit(ColumnId::kPosition)) {
  nodes_ = SelectNodes(dataset, region, options, stats_.selection);
  stats_.nodes_selected = nodes_.size();
  for (const IndexEntry& entry : nodes_) stats_.points_selected += entry.point_count;
  read_ahead_ = dataset.store().page_file(epoch_).remote();
}

std::optional<QueryCursor::Fetched> QueryCursor::NextBlock() {
  const auto read = [&dataset = dataset_, epoch = epoch_, wanted = wanted_](const IndexEntry& entry) {
    Fetched fetched;
    fetched.block = ReadBlockColumns(dataset, epoch, entry, wanted, fetched.counters);
    return fetched;
  };
  if (!read_ahead_) {
    if (next_node_ == nodes_.size()) return std::nullopt;
    return read(nodes_[next_node_++]);
  }
  // Each read from a server waits a round trip: keep several in flight,
  // handed out in selection order. The reads capture no part of the cursor,
  // which may move while they run.
  while (ahead_.size() < kReadsAhead && next_node_ < nodes_.size()) {
    ahead_.push_back(std::async(std::launch::async, read, nodes_[next_node_++]));
  }
  if (ahead_.empty()) return std::nullopt;
  Fetched fetched = ahead_.front().get();
  ahead_.pop_front();
  return fetched;
}

bool QueryCursor::Next(QueryBatch& batch) {
  while (std::optional<Fetched> fetched = NextBlock()) {
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
