// Camera paths for movies: `octocosm render --path path.json --frames DIR`.
//
//   {
//     "fps": 30,
//     "keyframes": [
//       {"t": 0, "camera": [x, y, z], "look_at": [x, y, z], "up": [0, 1, 0], "fov": 60, "epoch": 0},
//       {"t": 4, "camera": [x, y, z], "epoch": 2.5},
//       ...
//     ]
//   }
//
// `t` is the keyframe's time in seconds (strictly increasing; the first is
// usually 0). Each keyframe may leave out any member but `t`; it then keeps
// the previous keyframe's value (the first keyframe's defaults: look_at the
// cube's centre, up +y, fov 60, epoch 0; its camera is required). Instead of
// "epoch" a keyframe may give the physical time of a cosmological store,
// "redshift": z or "scale_factor": a (at most one of the three), which
// becomes a fractional epoch as --redshift does (Dataset::FractionalEpochAt).
// Between keyframes the camera position and the look-at point follow
// Catmull-Rom splines through the keyframes (smooth at every keyframe), and
// fov, up and the epoch time (a fractional epoch: the renderer interpolates
// between epochs) change linearly. Frames are taken every 1/fps seconds from
// the first keyframe's t to the last's.
#pragma once

#include <array>
#include <functional>
#include <string>
#include <vector>

#include "index/cube.h"
#include "index/dataset.h"
#include "query/frustum.h"

namespace octocosm {

struct CameraKeyframe {
  double t = 0;
  std::array<double, 3> position{};
  std::array<double, 3> look_at{};
  std::array<double, 3> up{0, 1, 0};
  double fov = 60;
  double epoch = 0;
};

struct CameraPathFrame {
  Camera camera;
  double epoch = 0;
};

class CameraPath {
 public:
  // A keyframe's "redshift" or "scale_factor" as a fractional epoch.
  using EpochAt = std::function<double(const PhysicalTime&)>;

  // Throws Error::NotFound when the file is missing and Error::BadInput
  // naming the file (and the keyframe) for anything malformed; an error of
  // `epoch_at` (Error::InvalidArgument for a time the store does not hold)
  // comes back naming the file and the keyframe too, of the same kind.
  static CameraPath Load(const std::string& path, const Cube& cube, const EpochAt& epoch_at);
  // Load with the times of `dataset`'s epochs.
  static CameraPath Load(const std::string& path, const Cube& cube, const Dataset& dataset);
  static CameraPath FromKeyframes(std::vector<CameraKeyframe> keyframes, double fps);

  double fps() const { return fps_; }
  std::size_t frame_count() const;
  // Frame `index` (0 .. frame_count() - 1), with `aspect`, near and far set by the caller.
  CameraPathFrame Frame(std::size_t index) const;
  const std::vector<CameraKeyframe>& keyframes() const { return keyframes_; }

 private:
  std::vector<CameraKeyframe> keyframes_;
  double fps_ = 30;
};

}  // namespace octocosm
