// The viewer's camera controller (tools/viewer/camera_controller.h): orbit
// and fly arithmetic, checked against the properties each control promises,
// with RenderView's projection as the judge of what moves on the screen.
#include "tools/viewer/camera_controller.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "render/render_view.h"
#include "tools/camera_flags.h"

namespace octocosm {
namespace {

using Vec = std::array<double, 3>;

Vec Sub(const Vec& a, const Vec& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
double Dot(const Vec& a, const Vec& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double Length(const Vec& a) { return std::sqrt(Dot(a, a)); }
double AngleDegrees(const Vec& a, const Vec& b) {
  return std::acos(std::clamp(Dot(a, b) / (Length(a) * Length(b)), -1.0, 1.0)) * 180 / std::numbers::pi;
}

constexpr double kCube = 1000;
constexpr int kWidth = 640, kHeight = 360;
constexpr double kAspect = static_cast<double>(kWidth) / kHeight;

Camera OverviewCamera(double cube_size = kCube) {
  const Cube cube{{0, 0, 0}, cube_size, false};
  Camera c;
  c.position = OverviewPosition(cube, 60);
  c.look_at = {cube_size / 2, cube_size / 2, cube_size / 2};
  c.fov_y_degrees = 60;
  return c;
}

void ExpectNear(const Vec& a, const Vec& b, double tolerance, const std::string& what) {
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(a[i], b[i], tolerance) << what << " [" << i << "]";
}

CameraInput Drag(double dx, double dy) {
  CameraInput in;
  in.rotate_x = dx;
  in.rotate_y = dy;
  return in;
}

TEST(CameraControllerTest, StartsAtTheGivenCameraWithItsLookAtAsThePivot) {
  const Camera start = OverviewCamera();
  const CameraController controller(start, kCube);
  const Camera c = controller.camera(kAspect);
  ExpectNear(c.position, start.position, 1e-9, "position");
  ExpectNear(c.Forward(), start.Forward(), 1e-12, "forward");
  ExpectNear(controller.pivot(), start.look_at, 1e-9, "pivot");
  EXPECT_NEAR(controller.distance(), Length(Sub(start.look_at, start.position)), 1e-9);
  EXPECT_EQ(c.aspect, kAspect);
  EXPECT_EQ(controller.mode(), CameraMode::kOrbit);
}

TEST(CameraControllerTest, OrbitingKeepsThePivotAndTheDistance) {
  CameraController controller(OverviewCamera(), kCube);
  const Vec pivot = controller.pivot();
  const double distance = controller.distance();
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> pixels(-200, 200);
  for (int i = 0; i < 200; ++i) {
    controller.Update(Drag(pixels(rng), pixels(rng)), kHeight);
    const Camera c = controller.camera(kAspect);
    ASSERT_NO_THROW(c.Validate());
    ExpectNear(controller.pivot(), pivot, 1e-9 * kCube, "pivot after drag " + std::to_string(i));
    EXPECT_NEAR(Length(Sub(pivot, c.position)), distance, 1e-9 * kCube);
  }
}

// Dragging right turns the view right: orbiting, the camera goes round the
// pivot to its left; dragging down turns it down: the camera rises.
TEST(CameraControllerTest, OrbitDragsTurnTheViewTheWayTheCursorMoves) {
  const Camera start = OverviewCamera();
  {
    CameraController controller(start, kCube);
    controller.Update(Drag(20, 0), kHeight);
    const Camera c = controller.camera(kAspect);
    EXPECT_LT(Dot(Sub(c.position, start.position), start.Right()), 0) << "the camera moves to its left";
    EXPECT_GT(Dot(c.Forward(), start.Right()), 0) << "the view turns right";
    EXPECT_NEAR(AngleDegrees(c.Forward(), start.Forward()), 20 * CameraController::kRadiansPerPixel * 180 / std::numbers::pi,
                1e-9);
  }
  {
    CameraController controller(start, kCube);
    controller.Update(Drag(0, 20), kHeight);
    const Camera c = controller.camera(kAspect);
    EXPECT_GT(Dot(Sub(c.position, start.position), start.up), 0) << "the camera rises";
    EXPECT_LT(Dot(c.Forward(), start.up), Dot(start.Forward(), start.up)) << "the view turns down";
  }
}

TEST(CameraControllerTest, AFullTurnAroundThePivotComesBack) {
  const Camera start = OverviewCamera();
  CameraController controller(start, kCube);
  const double full_turn_pixels = 2 * std::numbers::pi / CameraController::kRadiansPerPixel;
  for (int i = 0; i < 100; ++i) controller.Update(Drag(full_turn_pixels / 100, 0), kHeight);
  ExpectNear(controller.camera(kAspect).position, start.position, 1e-9 * kCube, "position after 360 degrees");
}

TEST(CameraControllerTest, PitchStopsShortOfStraightUpOrDown) {
  for (const double dy : {1e6, -1e6}) {
    for (const CameraMode mode : {CameraMode::kOrbit, CameraMode::kFly}) {
      CameraController controller(OverviewCamera(), kCube);
      controller.set_mode(mode);
      controller.Update(Drag(0, dy), kHeight);
      const Camera c = controller.camera(kAspect);
      ASSERT_NO_THROW(c.Validate());
      const double from_up = AngleDegrees(c.Forward(), c.up);
      EXPECT_GT(std::min(from_up, 180 - from_up), 0.5) << "dy " << dy << ", " << CameraModeName(mode);
      // ...and the view still turns back.
      controller.Update(Drag(0, -dy / 1e6 * 10), kHeight);
      const double after = AngleDegrees(controller.camera(kAspect).Forward(), c.up);
      EXPECT_GT(std::min(after, 180 - after), std::min(from_up, 180 - from_up));
    }
  }
}

TEST(CameraControllerTest, ScrollingMovesTowardsThePivotAndNeverThroughIt) {
  const Camera start = OverviewCamera();
  CameraController controller(start, kCube);
  const double distance = controller.distance();
  CameraInput in;
  in.scroll = 1;
  controller.Update(in, kHeight);
  EXPECT_NEAR(controller.distance(), distance / CameraController::kZoomPerNotch, 1e-9 * distance);
  ExpectNear(controller.pivot(), start.look_at, 1e-9 * kCube, "pivot");
  ExpectNear(controller.camera(kAspect).Forward(), start.Forward(), 1e-12, "forward");
  in.scroll = 1000;
  controller.Update(in, kHeight);
  EXPECT_GT(controller.distance(), 0);
  EXPECT_GE(controller.distance(), 1e-6 * kCube * (1 - 1e-12));
  EXPECT_NO_THROW(controller.camera(kAspect).Validate());
  in.scroll = -1000;
  controller.Update(in, kHeight);
  EXPECT_LE(controller.distance(), 1e3 * kCube * (1 + 1e-12));
}

// A pan of n pixels moves the pivot n pixels on the screen, with the cursor.
TEST(CameraControllerTest, PanningMovesThePivotWithTheCursor) {
  const Camera start = OverviewCamera();
  CameraController controller(start, kCube);
  const Vec pivot = controller.pivot();
  CameraInput in;
  in.pan_x = 40;  // right
  in.pan_y = 25;  // down
  controller.Update(in, kHeight);
  Camera after = controller.camera(kAspect);
  after.near = 1e-3;
  after.far = 1e9;
  const RenderView view(after, kWidth, kHeight);
  ProjectedPoint p;
  ASSERT_TRUE(view.Project(pivot.data(), p));
  // Window coordinates have y up: down on the screen is a smaller y.
  EXPECT_NEAR(p.x, kWidth / 2.0 + 40, 1e-6);
  EXPECT_NEAR(p.y, kHeight / 2.0 - 25, 1e-6);
  ExpectNear(after.Forward(), start.Forward(), 1e-12, "a pan does not turn the view");
  EXPECT_NEAR(controller.distance(), Length(Sub(start.look_at, start.position)), 1e-9 * kCube);
}

TEST(CameraControllerTest, FlyingMovesAtASpeedThatScalesWithTheCube) {
  for (const double cube : {1.0, kCube, 1e6}) {
    const Camera start = OverviewCamera(cube);
    CameraController controller(start, cube);
    controller.set_mode(CameraMode::kFly);
    CameraInput in;
    in.move = {0, 0, 1};  // W
    in.seconds = 2;
    controller.Update(in, kHeight);
    const Vec moved = Sub(controller.camera(kAspect).position, start.position);
    const double expected = CameraController::kFlySpeedPerCube * cube * 2;
    EXPECT_NEAR(Length(moved), expected, 1e-9 * expected) << "cube " << cube;
    EXPECT_NEAR(Dot(moved, start.Forward()), expected, 1e-9 * expected) << "along the view";
    ExpectNear(controller.camera(kAspect).Forward(), start.Forward(), 1e-12, "flying does not turn");

    const Vec before = controller.camera(kAspect).position;
    in.fast = true;
    in.move = {1, 0, 0};  // D, with shift
    controller.Update(in, kHeight);
    const Vec right = Sub(controller.camera(kAspect).position, before);
    EXPECT_NEAR(Dot(right, start.Right()), expected * CameraController::kFastFactor, 1e-9 * expected);
  }
}

TEST(CameraControllerTest, FlyingDiagonallyIsNoFasterAndUpIsTheWorldsUp) {
  const Camera start = OverviewCamera();
  CameraController controller(start, kCube);
  controller.set_mode(CameraMode::kFly);
  controller.Update(Drag(0, 100), kHeight);  // look down a little: up is then not the camera's up
  const Vec before = controller.camera(kAspect).position;
  CameraInput in;
  in.move = {1, 1, 1};
  in.seconds = 1;
  controller.Update(in, kHeight);
  EXPECT_NEAR(Length(Sub(controller.camera(kAspect).position, before)), controller.fly_speed(), 1e-9 * kCube);

  const Vec level = controller.camera(kAspect).position;
  in.move = {0, -1, 0};  // Q
  controller.Update(in, kHeight);
  ExpectNear(Sub(controller.camera(kAspect).position, level), {0, -controller.fly_speed(), 0}, 1e-9 * kCube, "down");
}

TEST(CameraControllerTest, MouseLookTurnsAboutTheCamera) {
  const Camera start = OverviewCamera();
  CameraController controller(start, kCube);
  controller.set_mode(CameraMode::kFly);
  controller.Update(Drag(30, -10), kHeight);
  const Camera c = controller.camera(kAspect);
  ExpectNear(c.position, start.position, 1e-9 * kCube, "the camera stays");
  EXPECT_GT(Dot(c.Forward(), start.Right()), 0) << "dragging right looks right";
  EXPECT_GT(Dot(c.Forward(), start.up), Dot(start.Forward(), start.up)) << "dragging up looks up";
}

TEST(CameraControllerTest, ScrollingWhileFlyingChangesTheSpeedNotThePlace) {
  const Camera start = OverviewCamera();
  CameraController controller(start, kCube);
  controller.set_mode(CameraMode::kFly);
  const double speed = controller.fly_speed();
  CameraInput in;
  in.scroll = 2;
  controller.Update(in, kHeight);
  EXPECT_NEAR(controller.fly_speed(), speed * CameraController::kSpeedPerNotch * CameraController::kSpeedPerNotch,
              1e-12 * speed);
  ExpectNear(controller.camera(kAspect).position, start.position, 0, "position");
}

TEST(CameraControllerTest, SwitchingModesKeepsTheView) {
  CameraController controller(OverviewCamera(), kCube);
  controller.Update(Drag(50, 30), kHeight);
  const Camera orbit = controller.camera(kAspect);
  controller.set_mode(CameraMode::kFly);
  const Camera fly = controller.camera(kAspect);
  ExpectNear(fly.position, orbit.position, 0, "position");
  ExpectNear(fly.look_at, orbit.look_at, 0, "look-at");
  // Flying away and switching back orbits about the point straight ahead.
  CameraInput in;
  in.move = {1, 0, 0};
  in.seconds = 1;
  controller.Update(in, kHeight);
  controller.set_mode(CameraMode::kOrbit);
  const Vec pivot = controller.pivot();
  controller.Update(Drag(40, 0), kHeight);
  ExpectNear(controller.pivot(), pivot, 1e-9 * kCube, "new pivot");
}

// Any up direction, and a camera that starts looking (almost) straight down it.
TEST(CameraControllerTest, WorksWithAnyUpAndAStartLookingAlongIt) {
  Camera start = OverviewCamera();
  start.up = {0, 0, 1};
  start.position = {500, 500, 3000};
  start.look_at = {500, 500.001, 500};  // almost straight down -z, i.e. along -up
  CameraController controller(start, kCube);
  Camera c = controller.camera(kAspect);
  ASSERT_NO_THROW(c.Validate());
  EXPECT_LT(AngleDegrees(c.Forward(), start.Forward()), 1) << "the pitch limit moves it at most a little";
  controller.Update(Drag(100, 0), kHeight);
  c = controller.camera(kAspect);
  ASSERT_NO_THROW(c.Validate());
  EXPECT_NEAR(Length(Sub(controller.pivot(), c.position)), controller.distance(), 1e-9 * kCube);
  // Turning sideways keeps the angle to up.
  CameraController sideways(OverviewCamera(), kCube);
  Camera tilted = OverviewCamera();
  tilted.up = {0, 0, 1};
  sideways.JumpTo(tilted);
  const double before = AngleDegrees(sideways.camera(kAspect).Forward(), tilted.up);
  sideways.Update(Drag(123, 0), kHeight);
  EXPECT_NEAR(AngleDegrees(sideways.camera(kAspect).Forward(), tilted.up), before, 1e-9);
}

}  // namespace
}  // namespace octocosm
