// The P key's screenshot is of the complete view. Frames never wait for the
// disk, so a frame drawn while blocks are still on their way shows parents
// standing in for their children: coarser than the same view a moment later.
// A request therefore waits for the first frame with no block of its view
// missing, and takes the picture as it is only when the view has not
// completed within kPatienceSeconds (the camera kept moving, or the disk is
// slow), saying so. Frames go on meanwhile.
//
// No window, no GL: the frame loop reports each frame drawn and writes the
// picture when told to.
#pragma once

#include <cstdint>
#include <optional>

namespace octocosm {

class ScreenshotRequest {
 public:
  static constexpr double kPatienceSeconds = 5;

  // Asks for a screenshot at `seconds` (any steady clock). Asking again while
  // one waits is the same request.
  void Ask(double seconds);
  bool waiting() const { return asked_at_.has_value(); }

  enum class Take {
    kNotYet,    // keep waiting (or nothing was asked)
    kComplete,  // this frame's view is complete: take it
    kAsItIs,    // waited kPatienceSeconds: take this frame with what has arrived
  };
  // For the frame just drawn at `seconds` with `blocks_missing` blocks of its
  // view not on the GPU. Anything but kNotYet ends the request.
  Take FrameDrawn(std::uint64_t blocks_missing, double seconds);

 private:
  std::optional<double> asked_at_;
};

}  // namespace octocosm
