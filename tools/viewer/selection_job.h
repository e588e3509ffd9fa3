// The viewer's selections, worked out on a background thread so that the
// frame loop never waits for the disk: the particles under a screen
// rectangle (every leaf in a frustum, query/particle_lookup.h) or the IDs
// of a file. One job counts at a time: starting another abandons the
// previous one (it is asked to stop and its result is dropped). The result
// is taken by the frame loop, which hands it to the GL thread's renderer
// (SceneRenderer::SetSelection).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include "index/dataset.h"
#include "query/frustum.h"

namespace octocosm {

// The most particles a box selection takes (the issue's "up to 10^6 selected
// particle IDs"); the rest of a larger box is left out, with a message.
inline constexpr std::size_t kMaxBoxSelection = 1'000'000;

struct SelectionResult {
  std::vector<std::uint64_t> ids;
  std::string message;  // what was selected, or what failed
  bool failed = false;
  double seconds = 0;
};

class SelectionJob {
 public:
  // Runs on the job's thread; should return soon after a stop is requested.
  using Work = std::function<SelectionResult(std::stop_token)>;

  SelectionJob() = default;
  SelectionJob(const SelectionJob&) = delete;
  SelectionJob& operator=(const SelectionJob&) = delete;
  // Asks every job to stop and waits for them (each stops after the block it
  // is reading).
  ~SelectionJob();

  // Starts `work`, abandoning the job running now, if any. An Error thrown
  // by `work` becomes a failed result naming it.
  void Start(Work work);
  // Abandons the job running now.
  void Cancel();
  bool running() const;
  // The result of the latest job once it has finished, once.
  std::optional<SelectionResult> TakeResult();

 private:
  struct Run {
    std::atomic<bool> done{false};
    SelectionResult result;
    std::jthread thread;  // last: joined first when a Run is destroyed
  };
  void ForgetFinished();

  std::unique_ptr<Run> current_;
  std::vector<std::unique_ptr<Run>> abandoned_;  // asked to stop; joined once done
};

// The particles of `epoch` in `frustum`, at most kMaxBoxSelection of them.
// `dataset` must outlive the job.
SelectionJob::Work BoxSelectionWork(const Dataset& dataset, std::uint32_t epoch, const Frustum& frustum);
// The IDs listed in the file (tools/cmd_query.h ReadIdFile).
SelectionJob::Work IdFileSelectionWork(const std::string& path);

}  // namespace octocosm
