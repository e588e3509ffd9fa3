#include "render/selection_overlay.h"

#include <chrono>
#include <exception>

#include "base/error.h"
#include "query/particle_lookup.h"

namespace octocosm {

SelectionOverlay::SelectionOverlay(const Dataset& dataset, GpuBlockArena& arena, std::uint32_t epoch,
                                   std::shared_ptr<const std::vector<std::uint64_t>> ids, ColumnSet columns)
    : dataset_(dataset), arena_(arena), epoch_(epoch), columns_(columns), lookup_(std::make_unique<Lookup>()) {
  Lookup* lookup = lookup_.get();
  lookup->thread = std::jthread([lookup, &dataset, epoch, ids = std::move(ids), columns](std::stop_token stop) {
    try {
      ParticleLocator locator(dataset);
      const Cube& cube = dataset.cube(epoch);
      for (const LeafSubset& subset : locator.LeafSubsetsInEpoch(epoch, *ids, columns, stop)) {
        lookup->keys.push_back(subset.leaf);
        lookup->blocks.push_back(EncodeBlock(subset.points, subset.leaf, cube));
      }
    } catch (const Error& e) {
      lookup->error = e;
    } catch (const std::exception& e) {
      lookup->error = Error::Io(dataset.store().directory(), std::string("looking up the selection: ") + e.what());
    }
    lookup->done.store(true, std::memory_order_release);
  });
}

SelectionOverlay::~SelectionOverlay() = default;

bool SelectionOverlay::Ready(bool wait) {
  if (!lookup_) return true;
  if (!lookup_->done.load(std::memory_order_acquire)) {
    if (!wait) return false;
    lookup_->thread.join();
  }
  if (lookup_->error) throw *lookup_->error;
  for (std::size_t i = 0; i < lookup_->blocks.size(); ++i) {
    const Bytes& bytes = lookup_->blocks[i];
    const std::string where = dataset_.Where(epoch_, lookup_->keys[i]) + " (selected particles)";
    const BlockHeader header = DecodeBlockHeader(bytes, lookup_->keys[i], where);
    blocks_.push_back(GpuBlock::Upload(arena_, bytes, header, dataset_.cube(epoch_).NodeCubeOf(lookup_->keys[i]), where));
    points_ += header.point_count;
  }
  lookup_.reset();
  return true;
}

std::size_t SelectionOverlay::gpu_bytes() const {
  std::size_t bytes = 0;
  for (const GpuBlock& block : blocks_) bytes += block.gpu_bytes();
  return bytes;
}

}  // namespace octocosm
