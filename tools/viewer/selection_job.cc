#include "tools/viewer/selection_job.h"

#include <chrono>
#include <exception>

#include "base/error.h"
#include "query/particle_lookup.h"
#include "query/region.h"
#include "tools/cmd_query.h"

namespace octocosm {

SelectionJob::~SelectionJob() {
  Cancel();
  abandoned_.clear();  // each Run's jthread asks its thread to stop and joins it
}

void SelectionJob::Start(Work work) {
  Cancel();
  ForgetFinished();
  current_ = std::make_unique<Run>();
  Run* run = current_.get();
  run->thread = std::jthread([run, work = std::move(work)](std::stop_token stop) {
    const auto start = std::chrono::steady_clock::now();
    try {
      run->result = work(stop);
    } catch (const std::exception& e) {
      run->result = SelectionResult{{}, std::string("selection failed: ") + e.what(), true, 0};
    }
    run->result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    run->done.store(true, std::memory_order_release);
  });
}

void SelectionJob::Cancel() {
  if (!current_) return;
  current_->thread.request_stop();
  abandoned_.push_back(std::move(current_));
}

bool SelectionJob::running() const { return current_ && !current_->done.load(std::memory_order_acquire); }

std::optional<SelectionResult> SelectionJob::TakeResult() {
  ForgetFinished();
  if (!current_ || !current_->done.load(std::memory_order_acquire)) return std::nullopt;
  SelectionResult result = std::move(current_->result);
  current_.reset();  // the thread has finished: joining it does not wait
  return result;
}

void SelectionJob::ForgetFinished() {
  std::erase_if(abandoned_, [](const std::unique_ptr<Run>& run) { return run->done.load(std::memory_order_acquire); });
}

SelectionJob::Work BoxSelectionWork(const Dataset& dataset, std::uint32_t epoch, const Frustum& frustum) {
  return [&dataset, epoch, frustum](std::stop_token stop) {
    const std::unique_ptr<Region> region = MakeFrustumRegion(frustum);
    ParticleIdCollection found = ParticleIdsInRegion(dataset, epoch, *region, kMaxBoxSelection, stop);
    SelectionResult result;
    result.message = std::to_string(found.ids.size()) + " particles in the box, epoch " + std::to_string(epoch);
    if (found.truncated) {
      result.message += " (the box holds more: a selection keeps at most " + std::to_string(kMaxBoxSelection) + ")";
    }
    result.ids = std::move(found.ids);
    return result;
  };
}

SelectionJob::Work IdFileSelectionWork(const std::string& path) {
  return [path](std::stop_token) {
    SelectionResult result;
    result.ids = ReadIdFile(path);
    result.message = std::to_string(result.ids.size()) + " IDs from " + path;
    return result;
  };
}

}  // namespace octocosm
