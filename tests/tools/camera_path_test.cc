// Camera paths (tools/camera_path.h): keyframes whose time is a redshift or
// a scale factor instead of an epoch.
#include <gtest/gtest.h>

#include <fstream>
#include <string>
#include <vector>

#include "base/error.h"
#include "tests/support/temp_dir.h"
#include "tools/camera_path.h"

namespace octocosm {
namespace {

const Cube kCube{{0, 0, 0}, 100, true};

// Epochs at a = 0.1, 0.2, 0.5, 1 (z = 9, 4, 1, 0) of a store named "run7".
double EpochAt(const PhysicalTime& time) { return FractionalEpochAt({0.1, 0.2, 0.5, 1.0}, time, "run7"); }

std::string WritePath(const testing_support::TempDir& dir, const std::string& json) {
  const std::string file = (dir.path() / "path.json").string();
  std::ofstream(file) << json;
  return file;
}

TEST(CameraPath, KeyframesMayGiveARedshiftOrAScaleFactor) {
  testing_support::TempDir dir("camera-path-time");
  const std::string file = WritePath(dir, R"({"fps": 1, "keyframes": [
      {"t": 0, "camera": [50, 50, 300], "redshift": 4},
      {"t": 1, "scale_factor": 0.35},
      {"t": 2, "camera": [50, 50, 200]},
      {"t": 3, "epoch": 3}]})");
  const CameraPath path = CameraPath::Load(file, kCube, EpochAt);
  ASSERT_EQ(path.keyframes().size(), 4u);
  EXPECT_EQ(path.keyframes()[0].epoch, 1.0);  // z = 4 is epoch 1's own time
  EXPECT_DOUBLE_EQ(path.keyframes()[1].epoch, 1.5);  // a = 0.35: halfway from a = 0.2 to 0.5
  EXPECT_DOUBLE_EQ(path.keyframes()[2].epoch, 1.5);  // kept from the keyframe before
  EXPECT_EQ(path.keyframes()[3].epoch, 3.0);
  ASSERT_EQ(path.frame_count(), 4u);
  EXPECT_DOUBLE_EQ(path.Frame(1).epoch, 1.5);
}

TEST(CameraPath, AKeyframeGivesOneTime) {
  testing_support::TempDir dir("camera-path-two-times");
  const std::string file = WritePath(dir, R"({"keyframes": [
      {"t": 0, "camera": [50, 50, 300], "epoch": 1, "redshift": 4}]})");
  try {
    CameraPath::Load(file, kCube, EpochAt);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kBadInput);
    EXPECT_NE(std::string(e.what()).find("keyframe 0"), std::string::npos) << e.what();
  }
}

TEST(CameraPath, ATimeTheStoreDoesNotHoldNamesTheFileTheKeyframeAndTheStore) {
  testing_support::TempDir dir("camera-path-outside");
  const std::string file = WritePath(dir, R"({"keyframes": [
      {"t": 0, "camera": [50, 50, 300], "redshift": 4},
      {"t": 1, "redshift": 20}]})");
  try {
    CameraPath::Load(file, kCube, EpochAt);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kInvalidArgument);
    const std::string message = e.what();
    for (const std::string& part : {file, std::string("keyframe 1"), std::string("run7"), std::string("redshift 20")}) {
      EXPECT_NE(message.find(part), std::string::npos) << message;
    }
  }
}

}  // namespace
}  // namespace octocosm
