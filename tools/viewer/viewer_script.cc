#include "tools/viewer/viewer_script.h"

#include <cstdio>

#include "base/error.h"

namespace octocosm {

ViewerScript::ViewerScript(ViewerScriptOptions options) : options_(std::move(options)) {
  if (options_.path && options_.path->frame_count() > 1) {
    state_ = State::kPlayingPath;
  } else if (options_.path || !options_.screenshot.empty() || options_.exit_after) {
    state_ = State::kSettling;
  } else {
    state_ = State::kDone;
  }
}

std::optional<CameraPathFrame> ViewerScript::PathFrame() const {
  if (!options_.path || state_ == State::kDone) return std::nullopt;
  return options_.path->Frame(frame_);
}

ViewerScript::AfterFrame ViewerScript::FrameDrawn(std::uint64_t blocks_missing, double seconds) {
  AfterFrame after;
  switch (state_) {
    case State::kPlayingPath:
      if (++frame_ + 1 >= options_.path->frame_count()) state_ = State::kSettling;
      break;
    case State::kSettling:
      if (!settle_start_) settle_start_ = seconds;
      if (blocks_missing == 0) {
        state_ = State::kDone;
        after.take_screenshot = !options_.screenshot.empty();
        after.quit = options_.exit_after;
      } else if (seconds - *settle_start_ > options_.settle_timeout) {
        char text[160];
        std::snprintf(text, sizeof text,
                      "the script's last view still misses %llu blocks after %.0f s of loading (--settle-timeout)",
                      static_cast<unsigned long long>(blocks_missing), options_.settle_timeout);
        throw Error::Io(options_.store, text);
      }
      break;
    case State::kDone:
      break;
  }
  return after;
}

}  // namespace octocosm
