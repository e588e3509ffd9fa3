// The viewer's clock through the epochs: a fractional epoch time in
// [0, epochs - 1], played forward at a speed in epochs per second, stopping
// at the last epoch or looping back to the first. Pure arithmetic; the
// renderer interpolates whatever time it is given (render/scene_renderer.h).
#pragma once

#include <cstdint>

namespace octocosm {

class Playback {
 public:
  // `time` is clamped to the epochs.
  Playback(std::uint32_t epochs, double time);

  // Moves the time on by `seconds` of playing; nothing when paused. At the
  // last epoch it wraps to the first when looping, else stops there and pauses.
  void Advance(double seconds);

  // Playing from the last epoch without looping starts again from the first.
  void set_playing(bool playing);
  void Toggle() { set_playing(!playing_); }
  void set_time(double time);
  // A whole epoch back or forward from the current time, rounded to the
  // epoch (stepping from 2.4 forward goes to 3, back to 2), within the epochs.
  void Step(int epochs);
  void set_speed(double epochs_per_second) { speed_ = epochs_per_second > 0 ? epochs_per_second : 0; }
  void set_loop(bool loop) { loop_ = loop; }

  double time() const { return time_; }
  double last() const { return last_; }
  bool playing() const { return playing_; }
  double speed() const { return speed_; }
  bool loop() const { return loop_; }

 private:
  double last_;
  double time_ = 0;
  bool playing_ = false;
  double speed_ = 0.5;
  bool loop_ = true;
};

}  // namespace octocosm
