// The viewer's parts that need no window (tools/viewer/): the playback
// clock, the frustum under a screen rectangle, the scripted run, the P key's
// screenshot request, and the background selection job.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <random>
#include <thread>

#include "base/error.h"
#include "render/render_view.h"
#include "tools/viewer/playback.h"
#include "tools/viewer/screen_region.h"
#include "tools/viewer/screenshot_request.h"
#include "tools/viewer/selection_job.h"
#include "tools/viewer/viewer_script.h"

namespace octocosm {
namespace {

// --- Playback ---

TEST(PlaybackTest, PlaysAtItsSpeedAndStopsAtTheLastEpochWithoutLoop) {
  Playback playback(5, 0);
  playback.set_speed(2);
  playback.set_loop(false);
  playback.Advance(1);
  EXPECT_EQ(playback.time(), 0) << "paused: the clock stands";
  playback.set_playing(true);
  playback.Advance(0.25);
  EXPECT_DOUBLE_EQ(playback.time(), 0.5);
  playback.Advance(10);
  EXPECT_EQ(playback.time(), 4);
  EXPECT_FALSE(playback.playing());
  playback.set_playing(true);
  EXPECT_EQ(playback.time(), 0) << "playing again from the end starts over";
}

TEST(PlaybackTest, LoopsBackToTheFirstEpoch) {
  Playback playback(3, 1.5);
  playback.set_speed(1);
  playback.set_playing(true);
  playback.Advance(0.75);
  EXPECT_NEAR(playback.time(), 0.25, 1e-12);
  EXPECT_TRUE(playback.playing());
}

TEST(PlaybackTest, ClampsStepsAndCannotPlayOneEpoch) {
  Playback playback(4, 7);
  EXPECT_EQ(playback.time(), 3);
  playback.set_time(1.4);
  playback.Step(1);
  EXPECT_EQ(playback.time(), 2);
  playback.set_time(1.4);
  playback.Step(-1);
  EXPECT_EQ(playback.time(), 1);
  playback.Step(-5);
  EXPECT_EQ(playback.time(), 0);
  playback.set_speed(-3);
  EXPECT_EQ(playback.speed(), 0);

  Playback single(1, 0);
  single.set_playing(true);
  EXPECT_FALSE(single.playing());
  single.Advance(5);
  EXPECT_EQ(single.time(), 0);
}

// --- The frustum under a rectangle ---

RenderView TestView() {
  Camera c;
  c.position = {3, -2, 40};
  c.look_at = {0.5, 1, 0};
  c.up = {0.1, 1, 0};
  c.fov_y_degrees = 50;
  c.near = 5;
  c.far = 70;
  return RenderView(c, 400, 300);
}

// A point is in the rectangle's frustum exactly when the view projects it
// into the rectangle (points within a millionth of a pixel of an edge, where
// rounding may go either way, are not counted).
TEST(ScreenRegionTest, TheRectanglesFrustumHoldsWhatProjectsIntoTheRectangle) {
  const RenderView view = TestView();
  std::mt19937_64 rng(4);
  std::uniform_real_distribution<double> coordinate(-40, 40);
  std::uniform_real_distribution<double> x(-50, 450), y(-50, 350);
  int inside = 0, outside = 0;
  for (int trial = 0; trial < 20; ++trial) {
    ScreenRectangle r{x(rng), y(rng), 0, 0};
    r.x1 = r.x0 + std::uniform_real_distribution<double>(1, 300)(rng);
    r.y1 = r.y0 + std::uniform_real_distribution<double>(1, 200)(rng);
    const Frustum frustum = RectangleFrustum(view, r);
    for (int i = 0; i < 2000; ++i) {
      const double p[3] = {coordinate(rng), coordinate(rng), coordinate(rng) - 10};
      ProjectedPoint q;
      const bool projects = view.Project(p, q);
      const double to_edge = std::min({q.x - r.x0, r.x1 - q.x, q.y - r.y0, r.y1 - q.y});
      if (projects && std::fabs(to_edge) < 1e-6) continue;  // on an edge
      const bool expected = projects && q.x >= r.x0 && q.x <= r.x1 && q.y >= r.y0 && q.y <= r.y1;
      EXPECT_EQ(frustum.Contains(p), expected) << "trial " << trial << " point " << i;
      (expected ? inside : outside) += 1;
    }
  }
  EXPECT_GT(inside, 500);
  EXPECT_GT(outside, 500);
}

TEST(ScreenRegionTest, TheWholeScreenIsTheCamerasFrustum) {
  const RenderView view = TestView();
  const Frustum whole = RectangleFrustum(view, {0, 0, 400, 300});
  const Frustum camera = Frustum::FromCamera(view.camera());
  for (int i = 0; i < 6; ++i) {
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(whole.planes()[i].normal[a], camera.planes()[i].normal[a], 1e-12) << i;
    EXPECT_NEAR(whole.planes()[i].offset, camera.planes()[i].offset, 1e-9) << i;
  }
  EXPECT_THROW(RectangleFrustum(view, {10, 10, 10, 50}), Error);
}

// --- Scripted runs ---

CameraPath ThreeFramePath() {
  CameraKeyframe a, b;
  a.t = 0;
  a.position = {0, 0, 10};
  a.epoch = 0;
  b = a;
  b.t = 0.2;
  b.position = {0, 0, 20};
  b.epoch = 1;
  return CameraPath::FromKeyframes({a, b}, 10);
}

TEST(ViewerScriptTest, PlaysThePathThenWaitsForTheLastViewThenTakesTheScreenshot) {
  ViewerScriptOptions o;
  o.path = ThreeFramePath();
  o.screenshot = "out.png";
  o.exit_after = true;
  ViewerScript script(o);
  ASSERT_EQ(o.path->frame_count(), 3u);
  for (std::size_t k = 0; k < 3; ++k) {
    ASSERT_TRUE(script.running());
    EXPECT_EQ(script.settling(), k == 2) << k;
    EXPECT_DOUBLE_EQ(script.PathFrame()->epoch, o.path->Frame(k).epoch);
    const ViewerScript::AfterFrame after = script.FrameDrawn(5, 0.1 * static_cast<double>(k));  // blocks missing
    EXPECT_FALSE(after.take_screenshot);
    EXPECT_FALSE(after.quit);
  }
  // Still loading: the last view again.
  EXPECT_TRUE(script.settling());
  EXPECT_DOUBLE_EQ(script.PathFrame()->epoch, 1);
  EXPECT_FALSE(script.FrameDrawn(1, 0.5).take_screenshot);
  const ViewerScript::AfterFrame done = script.FrameDrawn(0, 0.6);
  EXPECT_TRUE(done.take_screenshot);
  EXPECT_TRUE(done.quit);
  EXPECT_FALSE(script.running());
  EXPECT_FALSE(script.PathFrame());
  EXPECT_FALSE(script.FrameDrawn(0, 0.7).take_screenshot) << "once";
}

TEST(ViewerScriptTest, WithoutAPathItWaitsAtTheStartingView) {
  ViewerScriptOptions o;
  o.screenshot = "out.png";
  ViewerScript script(o);
  EXPECT_TRUE(script.settling());
  EXPECT_FALSE(script.PathFrame());
  const ViewerScript::AfterFrame after = script.FrameDrawn(0, 0);
  EXPECT_TRUE(after.take_screenshot);
  EXPECT_FALSE(after.quit) << "the user takes over";

  EXPECT_FALSE(ViewerScript(ViewerScriptOptions{}).running()) << "no script at all";
}

TEST(ViewerScriptTest, ALastViewThatNeverCompletesIsAnIoErrorAfterTheTimeout) {
  ViewerScriptOptions o;
  o.store = "the-store";
  o.exit_after = true;
  o.settle_timeout = 2;
  ViewerScript script(o);
  script.FrameDrawn(3, 100);
  script.FrameDrawn(3, 101.9);
  try {
    script.FrameDrawn(3, 102.1);
    FAIL() << "no timeout";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kIo);
    EXPECT_NE(std::string(e.what()).find("the-store"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("3 blocks"), std::string::npos) << e.what();
  }
}

// --- The P key's screenshot ---

TEST(ScreenshotRequestTest, WaitsForTheCompleteViewThenTakesItOnce) {
  ScreenshotRequest request;
  EXPECT_EQ(request.FrameDrawn(0, 0), ScreenshotRequest::Take::kNotYet) << "nothing asked";
  request.Ask(10);
  EXPECT_TRUE(request.waiting());
  EXPECT_EQ(request.FrameDrawn(4, 10.1), ScreenshotRequest::Take::kNotYet);
  request.Ask(11);  // the same request
  EXPECT_EQ(request.FrameDrawn(1, 12), ScreenshotRequest::Take::kNotYet);
  EXPECT_EQ(request.FrameDrawn(0, 12.1), ScreenshotRequest::Take::kComplete);
  EXPECT_FALSE(request.waiting());
  EXPECT_EQ(request.FrameDrawn(0, 12.2), ScreenshotRequest::Take::kNotYet) << "once";

  request.Ask(20);
  EXPECT_EQ(request.FrameDrawn(0, 20), ScreenshotRequest::Take::kComplete) << "a complete view at once";
}

TEST(ScreenshotRequestTest, AViewThatDoesNotCompleteIsTakenAsItIsAfterThePatience) {
  ScreenshotRequest request;
  request.Ask(3);
  request.Ask(6);  // the same request: its patience counts from 3
  EXPECT_EQ(request.FrameDrawn(2, 3 + ScreenshotRequest::kPatienceSeconds - 0.01), ScreenshotRequest::Take::kNotYet);
  EXPECT_EQ(request.FrameDrawn(2, 3 + ScreenshotRequest::kPatienceSeconds), ScreenshotRequest::Take::kAsItIs);
  EXPECT_FALSE(request.waiting());
}

// --- The background selection job ---

// Work that runs until it is asked to stop, then says so.
SelectionResult UntilStopped(std::stop_token stop) {
  while (!stop.stop_requested()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  return SelectionResult{{1}, "stopped", false, 0};
}

SelectionResult Finished(std::stop_token) { return SelectionResult{{7, 8, 9}, "three", false, 0}; }

// The job's result, waiting as long as a loaded machine may need (a minute:
// the work itself takes microseconds).
std::optional<SelectionResult> WaitForResult(SelectionJob& job) {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::minutes(1);
  while (std::chrono::steady_clock::now() < give_up) {
    if (std::optional<SelectionResult> result = job.TakeResult()) return result;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return std::nullopt;
}

TEST(SelectionJobTest, TheLatestJobsResultComesOnceAndAbandonedJobsAreDropped) {
  SelectionJob job;
  job.Start(UntilStopped);
  EXPECT_TRUE(job.running());
  EXPECT_FALSE(job.TakeResult());
  job.Start(Finished);  // abandons the first
  const std::optional<SelectionResult> result = WaitForResult(job);
  ASSERT_TRUE(result);
  EXPECT_EQ(result->ids, (std::vector<std::uint64_t>{7, 8, 9}));
  EXPECT_EQ(result->message, "three");
  EXPECT_FALSE(job.running());
  EXPECT_FALSE(job.TakeResult()) << "once";

  job.Start(UntilStopped);
  job.Cancel();
  EXPECT_FALSE(job.running());
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_FALSE(job.TakeResult()) << "a cancelled job has no result";
}

TEST(SelectionJobTest, AnErrorBecomesAFailedResultNamingIt) {
  SelectionJob job;
  job.Start([](std::stop_token) -> SelectionResult { throw Error::NotFound("ids.txt"); });
  const std::optional<SelectionResult> result = WaitForResult(job);
  ASSERT_TRUE(result);
  EXPECT_TRUE(result->failed);
  EXPECT_NE(result->message.find("ids.txt"), std::string::npos) << result->message;
}

TEST(SelectionJobTest, DestroyingTheJobStopsWhatRuns) {
  const auto start = std::chrono::steady_clock::now();
  {
    SelectionJob job;
    job.Start(UntilStopped);
    job.Start(UntilStopped);
  }
  // Each job stops within a millisecond of being asked (one that never
  // stopped would hang the destructor until ctest's timeout); a minute
  // allows for any load.
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::minutes(1));
}

}  // namespace
}  // namespace octocosm
