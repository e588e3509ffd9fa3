#include "tools/viewer/screenshot_request.h"

namespace octocosm {

void ScreenshotRequest::Ask(double seconds) {
  if (!asked_at_) asked_at_ = seconds;
}

ScreenshotRequest::Take ScreenshotRequest::FrameDrawn(std::uint64_t blocks_missing, double seconds) {
  if (!asked_at_) return Take::kNotYet;
  Take take = Take::kNotYet;
  if (blocks_missing == 0) {
    take = Take::kComplete;
  } else if (seconds - *asked_at_ >= kPatienceSeconds) {
    take = Take::kAsItIs;
  }
  if (take != Take::kNotYet) asked_at_.reset();
  return take;
}

}  // namespace octocosm
