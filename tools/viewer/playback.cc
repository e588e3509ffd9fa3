#include "tools/viewer/playback.h"

#include <algorithm>
#include <cmath>

namespace octocosm {

Playback::Playback(std::uint32_t epochs, double time) : last_(epochs > 0 ? epochs - 1.0 : 0.0) { set_time(time); }

void Playback::set_time(double time) { time_ = std::clamp(std::isfinite(time) ? time : 0.0, 0.0, last_); }

void Playback::set_playing(bool playing) {
  // One epoch has nothing to play.
  playing_ = playing && last_ > 0;
  if (playing_ && !loop_ && time_ >= last_) time_ = 0;
}

void Playback::Advance(double seconds) {
  if (!playing_) return;
  time_ += speed_ * seconds;
  if (time_ < last_) return;
  if (loop_) {
    time_ = std::fmod(time_, last_);
  } else {
    time_ = last_;
    playing_ = false;
  }
}

void Playback::Step(int epochs) {
  const double from = epochs > 0 ? std::floor(time_ + 1e-9) : std::ceil(time_ - 1e-9);
  set_time(from + epochs);
}

}  // namespace octocosm
