// The selected particles of one epoch at full detail, on the GPU: what the
// renderer draws over any level of detail into the highlight channel alone
// (SplatRenderer::SetHighlightOnly), so that the highlighted mass is exactly
// that of the selected particles, each with its own smoothing length,
// however coarse the level that draws the rest. A coarse point that stands
// for a cluster could only be highlighted whole or not at all.
//
// The particles are found through the ID index (query/particle_lookup.h)
// and kept as small blocks, one per leaf that holds some, in the frame's
// columns, so the splat shader draws and moves them like any block. The
// look-up reads leaves from disk and runs on a worker thread; the upload
// happens on the GL thread once it is done.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "index/block_codec.h"
#include "index/dataset.h"
#include "render/gpu_block.h"

namespace octocosm {

class SelectionOverlay {
 public:
  // Starts looking up `ids` in `epoch` with the columns `columns`. `dataset`
  // and `arena` (where the blocks go on the GPU) must outlive the overlay;
  // the store must have an ID index.
  SelectionOverlay(const Dataset& dataset, GpuBlockArena& arena, std::uint32_t epoch,
                   std::shared_ptr<const std::vector<std::uint64_t>> ids, ColumnSet columns);
  // Asks the worker to stop and waits for it (it stops after the leaf it is
  // reading).
  ~SelectionOverlay();
  SelectionOverlay(const SelectionOverlay&) = delete;
  SelectionOverlay& operator=(const SelectionOverlay&) = delete;

  // Whether the blocks are on the GPU: uploads them once the look-up has
  // finished (needs the GL context), waiting for it when `wait`. Throws the
  // look-up's Error when it failed, each time asked.
  bool Ready(bool wait);

  std::uint32_t epoch() const { return epoch_; }
  ColumnSet columns() const { return columns_; }
  const std::vector<GpuBlock>& blocks() const { return blocks_; }
  std::uint64_t points() const { return points_; }
  std::size_t gpu_bytes() const;

 private:
  struct Lookup {
    std::atomic<bool> done{false};
    std::vector<NodeKey> keys;
    std::vector<Bytes> blocks;
    std::optional<Error> error;
    std::jthread thread;  // last: joined first when the Lookup is destroyed
  };

  const Dataset& dataset_;
  GpuBlockArena& arena_;
  std::uint32_t epoch_;
  ColumnSet columns_;
  std::unique_ptr<Lookup> lookup_;  // null once uploaded
  std::vector<GpuBlock> blocks_;
  std::uint64_t points_ = 0;
};

}  // namespace octocosm
