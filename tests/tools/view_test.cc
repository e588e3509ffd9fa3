// `octocosm view` end to end (ctest labels gl;viewer;xvfb): the real program
// in a virtual X display of the test's own (Xvfb; Mesa llvmpipe through
// GLX), driven along a scripted camera path, its screenshot compared with
// `octocosm render` of the same final camera, time, exposure and selection;
// driven by mouse and keyboard (x_input_driver.cc); and its errors.
//
// Nothing here can hang a run: every program runs under timeout(1), every
// wait of the input driver has a limit, and the Xvfb server ends with the
// test (virtual_display.h). Without Xvfb installed the tests that need a
// display are skipped, saying so.
//
// Tests of the viewer's parts without a window: camera_controller_test.cc,
// viewer_parts_test.cc.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "index/dataset.h"
#include "ingest/ingest.h"
#include "render/image_metrics.h"
#include "render/offscreen_renderer.h"
#include "tests/support/program_run.h"
#include "tests/support/temp_dir.h"
#include "tests/tools/virtual_display.h"
#include "tools/image_io.h"
#include "synth/scale_generator.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using testing_support::ProgramRun;
using testing_support::ReadText;
using testing_support::VirtualDisplay;

constexpr int kWidth = 320, kHeight = 180;
// Time limits, generous for AddressSanitizer builds on a loaded machine;
// the runs take a few seconds. ctest's own TIMEOUT (CMakeLists.txt) is above
// their sum.
constexpr int kProgramSeconds = 120;  // one octocosm run
constexpr int kSessionSeconds = 180;  // the interactive session, driver included

struct Stores {
  testing_support::TempDir dir{"view-test"};
  std::string with_ids;     // two epochs, with particle IDs
  std::string without_ids;  // one epoch, IDs not read
};

Stores* stores = nullptr;

// Runs `shell_command` under timeout(1) (tests/support/program_run.h).
ProgramRun RunCommand(const std::string& shell_command, int seconds, const std::string& environment = "") {
  return testing_support::RunCommand(shell_command, seconds, stores->dir.path() / "command.log", environment);
}

ProgramRun RunOctocosm(const std::string& args) {
  return RunCommand(std::string(OCTOCOSM_BINARY) + " " + args, kProgramSeconds);
}

class ViewTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    stores = new Stores;
    // Two epochs that look different: two draws of the same clustered
    // model (different seeds), the particles linked by their IDs.
    std::vector<std::string> snapshots;
    for (const std::uint64_t seed : {5, 6}) {
      synth::ScaleOptions s;
      s.output_directory = (stores->dir.path() / ("snap-" + std::to_string(seed))).string();
      s.particle_count = 60000;
      s.box_size_mpc_h = 20;
      s.files = 1;
      s.seed = seed;
      s.threads = 2;
      synth::RunScaleGenerator(s);
      snapshots.push_back((fs::path(s.output_directory) / s.snapshot_prefix).string());
    }
    IngestOptions o;
    o.inputs = snapshots;
    o.output = stores->with_ids = (stores->dir.path() / "store").string();
    o.tree.capacity = 2000;
    o.page_size = 16384;
    o.quiet = true;
    Ingest(o);
    o.inputs = {snapshots[0]};
    o.read.read_id = false;
    o.output = stores->without_ids = (stores->dir.path() / "store-without-ids").string();
    Ingest(o);
  }
  static void TearDownTestSuite() {
    delete stores;
    stores = nullptr;
  }

  static std::string File(const std::string& name) { return (stores->dir.path() / name).string(); }
};

// The tests that need a display get an Xvfb server of their own.
class ViewInDisplayTest : public ViewTest {
 protected:
  void SetUp() override {
    const std::string xvfb = VirtualDisplay::FindXvfb();
    if (xvfb.empty()) {
      GTEST_SKIP() << "Xvfb is not installed: no virtual display to run the viewer in "
                      "(apt-get install xvfb; tools/bootstrap.sh installs it)";
    }
    const std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    display_ = std::make_unique<VirtualDisplay>(xvfb, stores->dir.path() / ("xvfb-" + test + ".log"), 30);
  }

  ProgramRun RunInDisplay(const std::string& shell_command, int seconds) const {
    return RunCommand(shell_command, seconds, "DISPLAY=" + display_->name());
  }
  ProgramRun RunViewer(const std::string& args) const {
    return RunInDisplay(std::string(OCTOCOSM_BINARY) + " view " + args, kProgramSeconds);
  }

  std::unique_ptr<VirtualDisplay> display_;
};

std::string Triple(const std::array<double, 3>& v) {
  char text[100];
  std::snprintf(text, sizeof text, "%.17g,%.17g,%.17g", v[0], v[1], v[2]);
  return text;
}

std::string JsonTriple(const std::array<double, 3>& v) { return "[" + Triple(v) + "]"; }

// For render/image_metrics.h, which compares values in [0, 1].
DisplayImage FromBytes(const RgbImage& image) {
  DisplayImage d;
  d.width = image.width;
  d.height = image.height;
  d.rgb.assign(image.rgb.begin(), image.rgb.end());
  for (float& v : d.rgb) v /= 255;
  return d;
}

double Psnr(const RgbImage& a, const RgbImage& b) { return Psnr(FromBytes(a), FromBytes(b)); }

// Pixel (x, y) with y counted down from the top row, as on the screen (the
// image's rows run bottom to top, render/image.h).
const std::uint8_t* PixelFromTop(const RgbImage& image, int x, int y) {
  return image.rgb.data() + 3 * (static_cast<std::size_t>(image.height - 1 - y) * image.width + x);
}

// Lit: brighter than a dark grey in some channel. Highlighted: green leads
// red by a margin (the selection's colour).
bool Lit(const std::uint8_t* p) { return std::max({p[0], p[1], p[2]}) > 24; }
bool Highlighted(const std::uint8_t* p) { return p[1] > p[0] + 40; }

template <typename Test>
double Share(const RgbImage& image, const Test& test) {
  std::size_t count = 0;
  for (std::size_t i = 0; i < image.rgb.size(); i += 3) count += test(&image.rgb[i]);
  return static_cast<double>(count) / static_cast<double>(image.rgb.size() / 3);
}
double LitShare(const RgbImage& image) { return Share(image, Lit); }
double HighlightedShare(const RgbImage& image) { return Share(image, Highlighted); }

// Of the highlighted pixels, the share inside the rectangle [x0, x1] x
// [y0, y1] (screen pixels, y down) widened by `margin` on every side.
double HighlightedShareInside(const RgbImage& image, int x0, int y0, int x1, int y1, int margin) {
  std::size_t inside = 0, all = 0;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      if (!Highlighted(PixelFromTop(image, x, y))) continue;
      ++all;
      inside += x >= x0 - margin && x <= x1 + margin && y >= y0 - margin && y <= y1 + margin;
    }
  }
  return all == 0 ? 0 : static_cast<double>(inside) / static_cast<double>(all);
}

// The line of the viewer's stderr that holds `text`, or empty.
std::string LineWith(const std::string& log, const std::string& text) {
  std::stringstream lines(log);
  for (std::string line; std::getline(lines, line);) {
    if (line.find(text) != std::string::npos) return line;
  }
  return "";
}

// The viewer plays a camera path through both epochs, waits at the last view
// until every block of it is loaded, and writes the screenshot: it must be
// the picture `octocosm render` makes of that view (same camera, epoch,
// exposure and selection), to PSNR 40 dB. Measured: identical pictures
// (PSNR reported as 200), since the same Mesa rasterizes both with the same
// blocks in the same order; the bound leaves room for a GPU driver whose
// window and offscreen paths round differently. The same screenshot against
// `render` of the other epoch must score below 25 dB (measured 11), so the
// comparison can tell a wrong picture; neither picture is blank, and both
// show the selected particles.
TEST_F(ViewInDisplayTest, ScriptedScreenshotMatchesRenderOfTheLastView) {
  const Dataset dataset = Dataset::Open(stores->with_ids);
  const Cube& cube = dataset.cube(1);
  const double L = cube.size;
  const auto at = [&](double x, double y, double z) {
    return std::array<double, 3>{cube.origin[0] + x * L, cube.origin[1] + y * L, cube.origin[2] + z * L};
  };
  const std::array<double, 3> last_camera = at(0.9, 0.62, 1.25), last_look_at = at(0.45, 0.5, 0.45);
  const double last_fov = 50;
  {
    std::ofstream path(File("path.json"));
    path << "{\"fps\": 10, \"keyframes\": [\n"
         << "  {\"t\": 0, \"camera\": " << JsonTriple(at(0.5, 0.5, 2.2)) << ", \"epoch\": 0},\n"
         << "  {\"t\": 0.6, \"camera\": " << JsonTriple(at(1.3, 0.8, 1.5)) << ", \"epoch\": 0.5},\n"
         << "  {\"t\": 1.2, \"camera\": " << JsonTriple(last_camera) << ", \"look_at\": " << JsonTriple(last_look_at)
         << ", \"fov\": " << last_fov << ", \"epoch\": 1}\n"
         << "]}\n";
  }
  // One exposure for both, so that automatic exposure (smoothed over the
  // viewer's frames, taken from one frame by render) cannot differ: the
  // automatic exposure of the last view.
  Camera camera;
  camera.position = last_camera;
  camera.look_at = last_look_at;
  camera.fov_y_degrees = last_fov;
  camera.near = L * 1e-6;
  camera.far = 4 * L;
  double exposure = 0;
  {
    OffscreenRenderer renderer(dataset, HeadlessBackend::kOsMesa, SceneOptions{});
    exposure = renderer.Render(RenderView(camera, kWidth, kHeight), 1, ToneMapSettings{}, false).tone.exposure;
  }
  ASSERT_GT(exposure, 0);
  const std::string select_box = Triple(at(0.2, 0.2, 0.2)) + "," + Triple(at(0.7, 0.7, 0.7));
  char shared[600];
  std::snprintf(shared, sizeof shared, "%s --width %d --height %d --exposure %.17g --select-box %s",
                stores->with_ids.c_str(), kWidth, kHeight, exposure, select_box.c_str());

  // --time 1 for both: the viewer starts there (its path then sets the
  // time), and --select-box selects in that epoch.
  const ProgramRun view = RunViewer(std::string(shared) + " --time 1 --path " + File("path.json") + " --screenshot " +
                                    File("view.png") + " --exit-after-path --hide-overlay --no-vsync --settle-timeout 60");
  ASSERT_EQ(view.status, 0) << view.Describe();
  const std::string render = std::string("render ") + shared + " --camera " + Triple(last_camera) + " --look-at " +
                             Triple(last_look_at) + " --fov 50";
  const ProgramRun rendered_run = RunOctocosm(render + " --time 1 -o " + File("render.png"));
  ASSERT_EQ(rendered_run.status, 0) << rendered_run.Describe();
  // The other epoch from the same camera: what a wrong picture scores.
  const ProgramRun other = RunOctocosm(render + " --time 0 -o " + File("epoch0.png"));
  ASSERT_EQ(other.status, 0) << other.Describe();

  const RgbImage viewed = ReadPng(File("view.png"));
  const RgbImage rendered = ReadPng(File("render.png"));
  ASSERT_EQ(viewed.width, kWidth);
  ASSERT_EQ(viewed.height, kHeight);
  ASSERT_EQ(rendered.width, kWidth);
  ASSERT_EQ(rendered.height, kHeight);
  const double psnr = Psnr(viewed, rendered);
  const double wrong_epoch_psnr = Psnr(viewed, ReadPng(File("epoch0.png")));
  EXPECT_GT(psnr, 40);
  EXPECT_LT(wrong_epoch_psnr, 25) << "the two epochs should look different enough to tell them apart";
  EXPECT_GT(LitShare(viewed), 0.2) << "the screenshot is (nearly) blank";
  EXPECT_GT(HighlightedShare(viewed), 0.005) << "the selection is not highlighted";
  EXPECT_GT(HighlightedShare(rendered), 0.005);
  RecordProperty("psnr", std::to_string(psnr));
  std::printf("view vs render: PSNR %.1f dB (vs the other epoch: %.1f dB), lit %.3f, highlighted %.3f\n%s", psnr,
              wrong_epoch_psnr, LitShare(viewed), HighlightedShare(viewed), view.output.c_str());
}

// The mouse and keyboard, as a user would use them (x_input_driver plays
// XTEST input into the display), each step waiting for the viewer to report
// the last on stderr:
// - the starting view, once complete (--screenshot start.png), is what
//   `octocosm render` makes of the default camera (PSNR 40 dB; measured
//   identical) and has nothing highlighted;
// - shift + drag over the middle of the picture selects the particles under
//   the box; P's screenshot (of the complete view) shows them highlighted,
//   and only under the box (95% of the highlighted pixels within 6 pixels of
//   it; the rest are blobs reaching out of it);
// - F then W held flies forward: the next screenshot differs (below 30 dB
//   against the previous one; measured 15);
// - closing the window ends the viewer with status 0.
TEST_F(ViewInDisplayTest, MouseAndKeysSelectFlyAndTakeScreenshots) {
  const fs::path work = stores->dir.path() / "interactive";
  fs::create_directories(work);
  const std::string log = (work / "view.log").string();
  constexpr int kBoxX0 = 110, kBoxY0 = 50, kBoxX1 = 210, kBoxY1 = 130;
  char box[64];
  std::snprintf(box, sizeof box, "%d %d %d %d", kBoxX0, kBoxY0, kBoxX1, kBoxY1);
  const std::string viewer_args =
      stores->with_ids + " --width " + std::to_string(kWidth) + " --height " + std::to_string(kHeight) + " --exposure 30";
  // --foreground: in the session's process group, which the session's own
  // limit ends as a whole.
  const std::string viewer = "timeout --foreground -k 5 " + std::to_string(kSessionSeconds - 30) + " " +
                             OCTOCOSM_BINARY + " view " + viewer_args + " --hide-overlay --no-vsync --screenshot start.png";
  const std::string driver = std::string(X_INPUT_DRIVER) + " wait-text " + log + " start.png 60" +
                             " wait-window octocosm 10" +
                             " key-down Shift_L drag " + box + " key-up Shift_L" +
                             " wait-text " + log + " selection: 60" +
                             " tap p wait-text " + log + " octocosm-view-001.png 60" +
                             " tap f key-down w sleep 800 key-up w" +
                             " tap p wait-text " + log + " octocosm-view-002.png 60" +
                             " close";
  // The driver in the background, the viewer in the foreground: if the
  // viewer ends early, the driver is stopped instead of waiting out its limits.
  const ProgramRun run = RunInDisplay("cd " + work.string() + " || exit 1; " + driver + " & d=$!; " + viewer + " 2> " + log +
                                          "; v=$?; kill $d 2> /dev/null; wait $d; r=$?; "
                                          "echo viewer status $v, input driver status $r; [ $v = 0 ] && [ $r = 0 ]",
                                      kSessionSeconds);
  const std::string viewer_log = ReadText(log);
  ASSERT_EQ(run.status, 0) << run.Describe() << "viewer:\n" << viewer_log;
  const std::string selected_line = LineWith(viewer_log, "selection:");
  EXPECT_NE(selected_line.find("particles in the box"), std::string::npos) << viewer_log;
  EXPECT_EQ(selected_line.find("selection: 0 particles"), std::string::npos) << viewer_log;
  EXPECT_NE(LineWith(viewer_log, "octocosm-view-001.png").find("view complete"), std::string::npos) << viewer_log;
  EXPECT_NE(LineWith(viewer_log, "octocosm-view-002.png").find("view complete"), std::string::npos) << viewer_log;

  const ProgramRun rendered_run = RunOctocosm("render " + viewer_args + " -o " + File("start-render.png"));
  ASSERT_EQ(rendered_run.status, 0) << rendered_run.Describe();
  const RgbImage start = ReadPng((work / "start.png").string());
  const RgbImage start_rendered = ReadPng(File("start-render.png"));
  const RgbImage selected = ReadPng((work / "octocosm-view-001.png").string());
  const RgbImage flown = ReadPng((work / "octocosm-view-002.png").string());
  const double start_psnr = Psnr(start, start_rendered);
  EXPECT_GT(start_psnr, 40) << "the starting view is not render's default camera";
  EXPECT_GT(LitShare(start), 0.2) << "the starting view is (nearly) blank";
  EXPECT_LT(HighlightedShare(start), 0.001);
  EXPECT_GT(HighlightedShare(selected), 0.01) << "the box selected nothing";
  const double inside = HighlightedShareInside(selected, kBoxX0, kBoxY0, kBoxX1, kBoxY1, 6);
  EXPECT_GT(inside, 0.95) << "the selection is not what lies under the box";
  const double moved_psnr = Psnr(selected, flown);
  EXPECT_LT(moved_psnr, 30) << "flying forward did not change the picture";
  std::printf("start vs render: PSNR %.1f dB; highlighted: start %.4f, after the box %.4f (%.3f of it under the box); "
              "PSNR after flying %.1f dB\n%s%s",
              start_psnr, HighlightedShare(start), HighlightedShare(selected), inside, moved_psnr, viewer_log.c_str(),
              run.output.c_str());
}

TEST_F(ViewInDisplayTest, SelectingByBoxInAStoreWithoutIdsIsAClearError) {
  const ProgramRun view = RunViewer(stores->without_ids + " --select-box 0,0,0,1000,1000,1000 --exit-after-path");
  EXPECT_EQ(view.status, 2) << view.Describe();
  EXPECT_NE(view.output.find("holds no particle IDs"), std::string::npos) << view.Describe();
}

TEST_F(ViewInDisplayTest, AMissingStoreIsExitStatus5) {
  const ProgramRun view = RunViewer(File("no-such-store") + " --exit-after-path");
  EXPECT_EQ(view.status, 5) << view.Describe();
  EXPECT_NE(view.output.find("no-such-store"), std::string::npos) << view.Describe();
}

// Without a display the viewer says what it needs (exit status 6: not supported).
TEST_F(ViewTest, NoDisplayIsAClearError) {
  const ProgramRun view = RunCommand(std::string(OCTOCOSM_BINARY) + " view " + stores->with_ids + " --exit-after-path",
                                     kProgramSeconds, "env -u DISPLAY -u WAYLAND_DISPLAY");
  EXPECT_EQ(view.status, 6) << view.Describe();
  EXPECT_NE(view.output.find("needs a display"), std::string::npos) << view.Describe();
}

// Blocks of the last view that cannot be read: while streaming they are
// skipped (and shown in the overlay); a script, which promises the complete
// view, ends with the read's error (exit status 3, corruption, naming the
// block) instead of writing an incomplete screenshot.
TEST_F(ViewInDisplayTest, ACorruptBlockEndsAScriptWithTheReadsError) {
  const fs::path copy = stores->dir.path() / "damaged";
  fs::copy(stores->with_ids, copy, fs::copy_options::recursive);
  {
    // Bytes all through every block of epoch 0, so that each column the
    // viewer reads is hit; the index stays sound, so the store opens.
    const Dataset dataset = Dataset::Open(copy.string());
    std::vector<IndexEntry> blocks;
    dataset.store().Scan(0, 0, ~std::uint64_t{0}, [&](const IndexEntry& e) {
      blocks.push_back(e);
      return true;
    });
    std::fstream f(copy / dataset.store().epochs()[0].file, std::ios::in | std::ios::out | std::ios::binary);
    for (const IndexEntry& block : blocks) {
      for (std::uint64_t k = 1; k < 32; ++k) {
        const auto offset = static_cast<std::streamoff>(block.first_page * dataset.store().page_size() +
                                                        block.byte_length * k / 32);
        char c = 0;
        f.seekg(offset);
        f.read(&c, 1);
        c = static_cast<char>(c ^ 0x5A);
        f.seekp(offset);
        f.write(&c, 1);
      }
    }
  }
  const ProgramRun view = RunViewer(copy.string() + " --width 160 --height 90 --screenshot " + File("damaged.png") +
                                    " --exit-after-path --no-vsync --settle-timeout 60");
  EXPECT_EQ(view.status, 3) << view.Describe();
  EXPECT_NE(view.output.find("corruption"), std::string::npos) << view.Describe();
  EXPECT_NE(view.output.find("epoch 0"), std::string::npos) << view.Describe();
  EXPECT_FALSE(fs::exists(File("damaged.png")));
}

}  // namespace
}  // namespace octocosm
