#include "tools/camera_path.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <utility>

#include <nlohmann/json.hpp>

#include "base/error.h"

namespace octocosm {
namespace {

using Vec3 = std::array<double, 3>;

// Catmull-Rom (uniform) through p1 at s = 0 and p2 at s = 1.
Vec3 CatmullRom(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& p3, double s) {
  Vec3 r;
  const double s2 = s * s, s3 = s2 * s;
  for (int a = 0; a < 3; ++a) {
    r[a] = 0.5 * (2 * p1[a] + (-p0[a] + p2[a]) * s + (2 * p0[a] - 5 * p1[a] + 4 * p2[a] - p3[a]) * s2 +
                  (-p0[a] + 3 * p1[a] - 3 * p2[a] + p3[a]) * s3);
  }
  return r;
}

Vec3 Lerp(const Vec3& a, const Vec3& b, double s) { return {a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s, a[2] + (b[2] - a[2]) * s}; }

Vec3 ReadVec3(const nlohmann::json& j, const std::string& file, const std::string& where) {
  if (!j.is_array() || j.size() != 3) throw Error::BadInput(file, where + ": expected an array of 3 numbers");
  Vec3 v;
  for (int a = 0; a < 3; ++a) {
    if (!j[static_cast<std::size_t>(a)].is_number()) throw Error::BadInput(file, where + ": expected an array of 3 numbers");
    v[static_cast<std::size_t>(a)] = j[static_cast<std::size_t>(a)].get<double>();
    if (!std::isfinite(v[static_cast<std::size_t>(a)])) throw Error::BadInput(file, where + ": a number is not finite");
  }
  return v;
}

double ReadNumber(const nlohmann::json& j, const std::string& file, const std::string& where) {
  if (!j.is_number() || !std::isfinite(j.get<double>())) throw Error::BadInput(file, where + ": expected a finite number");
  return j.get<double>();
}

}  // namespace

CameraPath CameraPath::Load(const std::string& path, const Cube& cube, const Dataset& dataset) {
  return Load(path, cube, [&dataset](const PhysicalTime& time) { return dataset.FractionalEpochAt(time); });
}

CameraPath CameraPath::Load(const std::string& path, const Cube& cube, const EpochAt& epoch_at) {
  std::ifstream in(path);
  if (!in) throw Error::NotFound(path + ": cannot open the camera path");
  nlohmann::json j;
  try {
    in >> j;
  } catch (const nlohmann::json::exception& e) {
    throw Error::BadInput(path, std::string("not valid JSON: ") + e.what());
  }
  if (!j.is_object() || !j.contains("keyframes") || !j["keyframes"].is_array() || j["keyframes"].empty()) {
    throw Error::BadInput(path, "expected an object with a non-empty array \"keyframes\"");
  }
  const double fps = j.contains("fps") ? ReadNumber(j["fps"], path, "fps") : 30;
  std::vector<CameraKeyframe> keyframes;
  CameraKeyframe previous;
  previous.look_at = {cube.origin[0] + cube.size / 2, cube.origin[1] + cube.size / 2, cube.origin[2] + cube.size / 2};
  for (std::size_t k = 0; k < j["keyframes"].size(); ++k) {
    const nlohmann::json& f = j["keyframes"][k];
    const std::string where = "keyframe " + std::to_string(k);
    if (!f.is_object()) throw Error::BadInput(path, where + ": expected an object");
    if (!f.contains("t")) throw Error::BadInput(path, where + ": \"t\" (seconds) is required");
    if (k == 0 && !f.contains("camera")) throw Error::BadInput(path, where + ": the first keyframe needs \"camera\"");
    CameraKeyframe key = previous;
    key.t = ReadNumber(f["t"], path, where + " t");
    if (f.contains("camera")) key.position = ReadVec3(f["camera"], path, where + " camera");
    if (f.contains("look_at")) key.look_at = ReadVec3(f["look_at"], path, where + " look_at");
    if (f.contains("up")) key.up = ReadVec3(f["up"], path, where + " up");
    if (f.contains("fov")) key.fov = ReadNumber(f["fov"], path, where + " fov");
    if (f.contains("epoch") + f.contains("redshift") + f.contains("scale_factor") > 1) {
      throw Error::BadInput(path, where + ": give one of \"epoch\", \"redshift\" and \"scale_factor\"");
    }
    if (f.contains("epoch")) key.epoch = ReadNumber(f["epoch"], path, where + " epoch");
    for (const auto& [name, scale] : {std::pair{"redshift", PhysicalTime::Scale::kRedshift},
                                      std::pair{"scale_factor", PhysicalTime::Scale::kScaleFactor}}) {
      if (!f.contains(name)) continue;
      const PhysicalTime time{scale, ReadNumber(f[name], path, where + " " + name)};
      try {
        key.epoch = epoch_at(time);
      } catch (const Error& e) {
        throw Error(e.kind(), path + ": " + where + ": " + e.what());
      }
    }
    if (k > 0 && !(key.t > previous.t)) throw Error::BadInput(path, where + ": t must increase from keyframe to keyframe");
    keyframes.push_back(key);
    previous = key;
  }
  try {
    return FromKeyframes(std::move(keyframes), fps);
  } catch (const Error& e) {
    throw Error::BadInput(path, e.what());
  }
}

CameraPath CameraPath::FromKeyframes(std::vector<CameraKeyframe> keyframes, double fps) {
  if (keyframes.empty()) throw Error::InvalidArgument("a camera path needs at least one keyframe");
  if (!(fps > 0 && fps <= 1000)) throw Error::InvalidArgument("fps must be in (0, 1000]");
  for (std::size_t k = 1; k < keyframes.size(); ++k) {
    if (!(keyframes[k].t > keyframes[k - 1].t)) throw Error::InvalidArgument("keyframe times must increase");
  }
  CameraPath path;
  path.keyframes_ = std::move(keyframes);
  path.fps_ = fps;
  return path;
}

std::size_t CameraPath::frame_count() const {
  const double span = keyframes_.back().t - keyframes_.front().t;
  return static_cast<std::size_t>(std::floor(span * fps_ + 1e-9)) + 1;
}

CameraPathFrame CameraPath::Frame(std::size_t index) const {
  const double t = keyframes_.front().t + static_cast<double>(index) / fps_;
  std::size_t k = 0;
  while (k + 2 < keyframes_.size() && t >= keyframes_[k + 1].t) ++k;
  const CameraKeyframe& a = keyframes_[k];
  const CameraKeyframe& b = keyframes_[std::min(k + 1, keyframes_.size() - 1)];
  const CameraKeyframe& before = keyframes_[k > 0 ? k - 1 : k];
  const CameraKeyframe& after = keyframes_[std::min(k + 2, keyframes_.size() - 1)];
  const double s = b.t > a.t ? std::clamp((t - a.t) / (b.t - a.t), 0.0, 1.0) : 0.0;
  CameraPathFrame frame;
  frame.camera.position = CatmullRom(before.position, a.position, b.position, after.position, s);
  frame.camera.look_at = CatmullRom(before.look_at, a.look_at, b.look_at, after.look_at, s);
  frame.camera.up = Lerp(a.up, b.up, s);
  frame.camera.fov_y_degrees = a.fov + (b.fov - a.fov) * s;
  frame.epoch = a.epoch + (b.epoch - a.epoch) * s;
  return frame;
}

}  // namespace octocosm
