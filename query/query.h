// Spatial queries on one epoch of a dataset: the points of a level of detail
// (a level, or a screen-space error for a camera; query/node_selection.h)
// that lie in a region (box, sphere, frustum; query/region.h), with only the
// columns asked for.
//
// Cost: node selection reads index pages only; then each selected node's
// block is read once, in file order, fetching the header and the wanted
// columns only (query/column_reader.h). Results are streamed: the callback
// receives one batch per block, holding that block's points that lie in the
// region, so a result larger than memory is fine. Points come back in stored
// coordinates (see region.h for periodic boxes), dequantized to doubles.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <vector>

#include "index/block_codec.h"
#include "index/dataset.h"
#include "query/column_reader.h"
#include "query/node_selection.h"
#include "query/read_ahead.h"
#include "query/region.h"

namespace octocosm {

struct QueryOptions {
  std::uint32_t epoch = 0;
  // Exactly one level of detail: a level, or a screen-space error.
  std::optional<int> level;
  std::optional<ScreenErrorView> screen_error;
  // Columns to return besides the positions, which are always returned.
  ColumnSet columns = ColumnBit(ColumnId::kPosition);
};

struct QueryStats {
  SelectionStats selection;
  std::uint64_t nodes_selected = 0;
  std::uint64_t points_selected = 0;  // in the selected nodes: the most a query can return
  ReadCounters reads;  // blocks touched, positioned reads, bytes read
  std::uint64_t points_scanned = 0;   // points decoded
  std::uint64_t points_returned = 0;  // of those, the ones in the region
};

// One block's points in the region. `points` holds the wanted columns only
// (the others are empty) for the points[i] that are in the region, in block
// order; octant_offsets is not meaningful after filtering. `count` is the
// number of points (points.size() counts weights, which may not be wanted).
struct QueryBatch {
  NodeKey node;
  std::size_t count = 0;
  NodePoints points;
};

using QueryCallback = std::function<void(const QueryBatch&)>;

// A query read block by block at the caller's pace: the nodes are selected
// when it is made, and each Next() reads the next block that has points in
// the region. Throws as RunQuery. The dataset and region must outlive it.
class QueryCursor {
 public:
  QueryCursor(const Dataset& dataset, const Region& region, const QueryOptions& options);
  // Fills `batch` with the next block's points in the region; false when
  // every selected block has been read.
  bool Next(QueryBatch& batch);
  // What was selected, and read and returned so far.
  const QueryStats& stats() const { return stats_; }

 private:
  // A block read, with what reading it cost.
  struct Fetched {
    DecodedBlock block;
    ReadCounters counters;
  };
  const Region& region_;
  QueryStats stats_;
  // The selected blocks, read in selection order: now from a local store;
  // from a server, several in flight ahead of the caller.
  ReadAhead<IndexEntry, Fetched> blocks_;
  std::vector<std::uint32_t> keep_;
};

// Runs the query (a QueryCursor read to its end). Throws Error::InvalidArgument for bad options (no or two
// levels of detail, an epoch or level out of range, a bad camera), and
// Error::Corruption / Error::Io from the store; a callback may throw to stop.
QueryStats RunQuery(const Dataset& dataset, const Region& region, const QueryOptions& options,
                    const QueryCallback& callback);

// The node selection of RunQuery alone.
std::vector<IndexEntry> SelectNodes(const Dataset& dataset, const Region& region, const QueryOptions& options,
                                    SelectionStats& stats);

// Keeps the points whose index is in `keep` (ascending), in every non-empty column.
void KeepPoints(NodePoints& points, const std::vector<std::uint32_t>& keep);

}  // namespace octocosm
