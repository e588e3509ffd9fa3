// octocosm-bench-render: run time against error.
//
// On a generated clustered set (default 10^8 points, `octocosm synth scale`;
// or any snapshot, --snapshot),
// ingested once per representation of the inner nodes (--coarse: clusters,
// the default, drawn with their shapes or, as "round", without; and sample,
// a random subselection), three views at 1280x720 —
// the whole box, a mid zoom onto the densest halo, a deep zoom into it — are
// drawn:
//   - by the reference renderer (every particle of the snapshot, on the CPU,
//     in double precision: `octocosm render --reference`), timed;
//   - by the GPU renderer at full detail (every leaf in view), timed;
//   - by the GPU renderer at every pixel threshold x point budget of the
//     sweep, cold (block cache and OS page cache dropped) and warm (blocks on
//     the GPU), with points drawn, bytes read, and PSNR and SSIM of the picture
//     against the reference's, both tone mapped with the reference's exposure.
//     A frame's time ends when the GPU has drawn and tone mapped it, as a
//     viewer shows it; reading the picture back for the comparison is its own
//     column. Warm frames take the image statistics of the frame before, as
//     the viewer does (the same view: the same statistics).
// It prints a table, writes it as CSV, and draws error against points drawn
// and against time, per view and representation, with gnuplot (Debian's
// gnuplot-nox) as render_bench.png. Optionally: the frame
// time with 10^6 selected IDs against none.
//
// --playback STORE measures playback instead: the viewer's frame loop
// (streamed frames that never wait for the disk, the next epochs requested
// ahead) through every epoch of a multi-epoch store, interpolating.
//
// Generated data, the store and the reference images stay in --dir and are
// reused by later runs (delete them to start afresh).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "index/node_hierarchy.h"
#include "query/lod_frontier.h"
#include "render/image_metrics.h"
#include "render/offscreen_renderer.h"
#include "tools/camera_flags.h"
#include "tools/cli_util.h"
#include "tools/image_io.h"
#include "ingest/ingest.h"
#include "tools/reference_render.h"
#include "synth/scale_generator.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

struct Flags {
  std::string dir = "render-bench";
  double points = 1e8;
  double box = 500;
  int width = 1280, height = 720;
  std::string thresholds = "8,4,2,1,0.5", budgets = "0,1e6,4e6", views = "overview,mid,deep";
  std::string cluster_errors;  // the cut's thresholds (SceneOptions::cluster_error) on stores that link their clusters
  std::string coarse = "clusters,sample";  // inner nodes' representations to compare, a store each
  std::string snapshot;                    // an existing snapshot instead of a generated one
  std::size_t capacity = 0;                // points a node holds (0: ingest's default)
  std::string backend = "osmesa";
  std::string splat = "auto";  // splat paths to time (render/compute_splatter.h), the first also cold
  double compute_radius = 4;   // the compute path's largest blob, pixels
  bool full = true, selection = false, prepare_only = false;
  bool save_pictures = false;  // each swept frame's accumulation as PFM, beside the references
  bool reference = true;  // false: times only (no reference rendering, no PSNR or SSIM)
  unsigned threads = 0;
  std::string playback;  // a multi-epoch store: measure playback instead
  double playback_threshold = 1;
  int frames_per_epoch = 30;
};

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

struct NamedView {
  std::string name;
  Camera camera;
};

// The densest leaf (most points per volume among leaves that are at least an
// eighth full): the core of the most concentrated halo.
std::array<double, 3> DensestLeafCentre(const Dataset& dataset) {
  const NodeHierarchy h = NodeHierarchy::Load(dataset, 0);
  const Cube& cube = dataset.cube(0);
  double best = -1;
  std::array<double, 3> centre{};
  for (const NodeHierarchy::Node& n : h.nodes()) {
    if (!n.is_leaf() || n.entry.point_count * 8 < dataset.capacity()) continue;
    const NodeCube c = cube.NodeCubeOf(n.key);
    const double density = static_cast<double>(n.entry.point_count) / (c.size * c.size * c.size);
    if (density > best) {
      best = density;
      centre = {c.origin[0] + c.size / 2, c.origin[1] + c.size / 2, c.origin[2] + c.size / 2};
    }
  }
  return centre;
}

std::vector<NamedView> Views(const Dataset& dataset, const std::vector<std::string>& names) {
  const Cube& cube = dataset.cube(0);
  const std::array<double, 3> halo = DensestLeafCentre(dataset);
  std::vector<NamedView> views;
  for (const std::string& name : names) {
    Camera c;
    c.fov_y_degrees = 60;
    if (name == "overview") {
      c.position = OverviewPosition(cube, c.fov_y_degrees);
      c.look_at = {cube.origin[0] + cube.size / 2, cube.origin[1] + cube.size / 2, cube.origin[2] + cube.size / 2};
    } else if (name == "mid" || name == "deep") {
      // A halo seen slightly from above, from 6% or 0.6% of the box away.
      const double distance = cube.size * (name == "mid" ? 0.06 : 0.006);
      c.look_at = halo;
      c.position = {halo[0] + 0.3 * distance, halo[1] + 0.4 * distance, halo[2] + 0.866 * distance};
    } else {
      throw Error::InvalidArgument("--views: unknown view '" + name + "' (overview, mid, deep)");
    }
    double d2 = 0;
    for (int a = 0; a < 3; ++a) d2 += (c.position[a] - c.look_at[a]) * (c.position[a] - c.look_at[a]);
    c.near = std::sqrt(d2) * 1e-4;
    c.far = std::sqrt(d2) + 2 * cube.size;
    views.push_back({name, c});
  }
  return views;
}

// The view as `octocosm render` flags, to draw it again or hand it to
// bench/lod_oracle.py.
void PrintCameraFlags(const NamedView& view) {
  const Camera& c = view.camera;
  std::printf("%s: --camera %.17g,%.17g,%.17g --look-at %.17g,%.17g,%.17g --fov %g --near %.17g --far %.17g\n",
              view.name.c_str(), c.position[0], c.position[1], c.position[2], c.look_at[0], c.look_at[1], c.look_at[2],
              c.fov_y_degrees, c.near, c.far);
}

std::vector<std::string> Split(const std::string& text) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t comma = text.find(',', start);
    parts.push_back(text.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return parts;
}

struct Row {
  std::string view, mode, path;
  double threshold = 0;
  std::uint64_t budget = 0, points = 0, nodes = 0, bytes = 0;
  double cold = 0, warm = 0, psnr = 0, ssim = 0;
  // The warm frame's stages, milliseconds: on the CPU selecting nodes,
  // uploading blocks and issuing the draws; on the GPU drawing, measuring
  // and tone mapping (0 where the driver gave no timestamps); reading back.
  double select_ms = 0, upload_ms = 0, submit_ms = 0, gpu_draw_ms = 0, gpu_measure_ms = 0, gpu_tone_map_ms = 0,
         readback_ms = 0;
};

// Renders `view` with fresh caches, cold (nothing in memory, the OS page
// cache of the store dropped) and warm (every block on the GPU), on the first
// of `paths`; then warm on each other path with the same blocks. A row per
// path (the others' cold time and bytes are the first's).
std::vector<Row> Measure(const Dataset& dataset, SceneOptions options, const RenderView& view, HeadlessBackend backend,
                         const ToneMapParameters& tone, const DisplayImage& reference, const std::vector<SplatPath>& paths,
                         double compute_radius, const fs::path& save_as) {
  dataset.store().DropCaches();
  options.splat_path = paths.front();
  options.compute_radius = compute_radius;
  OffscreenRenderer renderer(dataset, backend, options);
  ToneMapSettings settings;
  settings.exposure = tone.exposure;
  const Picture cold = renderer.Render(view, 0, settings, false);
  const std::uint64_t bytes = renderer.scene().disk_reads().bytes;
  std::vector<Row> rows;
  renderer.SetStatisticsTiming(StatisticsTiming::kLatest);
  for (SplatPath path : paths) {
    renderer.scene().SetSplatPath(path);
    renderer.Render(view, 0, settings, false);  // builds the path's programs
    const Picture warm = renderer.Render(view, 0, settings, true);
    if (!save_as.empty() && path == paths.front()) WritePfm(save_as.string(), *warm.hdr);
    Row row;
    row.path = SplatPathName(renderer.splat().frame_path());
    row.points = warm.stats.points_drawn;
    row.nodes = warm.stats.nodes_selected;
    row.bytes = bytes;
    row.cold = cold.frame_seconds;
    row.warm = warm.frame_seconds;
    row.select_ms = warm.stats.select_ms;
    row.upload_ms = warm.stats.upload_ms;
    row.submit_ms = warm.stats.draw_ms;
    if (warm.gpu_times) {
      row.gpu_draw_ms = warm.gpu_times->draw_ms;
      row.gpu_measure_ms = warm.gpu_times->measure_ms;
      row.gpu_tone_map_ms = warm.gpu_times->tone_map_ms;
    }
    row.readback_ms = warm.readback_ms;
    if (!reference.rgb.empty()) {
      const DisplayImage picture = ToneMap(*warm.hdr, tone);
      row.psnr = Psnr(picture, reference);
      row.ssim = Ssim(picture, reference);
    }
    rows.push_back(row);
  }
  return rows;
}

void PrintRow(const Row& r) {
  std::printf("%-9s %-12s %9.3g %10llu %11llu %7llu %10s %9.3f %9.3f %7.2f %7.4f %7.1f %7.1f %7.1f %8.1f %7.1f %7.1f %7.1f %-7s\n",
              r.view.c_str(), r.mode.c_str(), r.threshold, static_cast<unsigned long long>(r.budget),
              static_cast<unsigned long long>(r.points), static_cast<unsigned long long>(r.nodes),
              HumanBytes(static_cast<double>(r.bytes)).c_str(), r.cold, r.warm, r.psnr, r.ssim, r.select_ms, r.upload_ms,
              r.submit_ms, r.gpu_draw_ms, r.gpu_measure_ms, r.gpu_tone_map_ms, r.readback_ms, r.path.c_str());
  std::fflush(stdout);
}

// Writes the rows as CSV and, with `errors` (a reference was rendered), the
// plot of error against points drawn and time.
void Plot(const fs::path& dir, const std::vector<Row>& rows, const std::vector<NamedView>& views, bool errors) {
  const fs::path data = dir / "render_bench.csv", script = dir / "render_bench.gp", png = dir / "render_bench.png";
  {
    std::ofstream csv(data);
    csv << "view,mode,threshold,budget,points,nodes,bytes_read,cold_s,warm_s,psnr_db,ssim,select_ms,upload_ms,submit_ms,"
           "gpu_draw_ms,gpu_measure_ms,gpu_tone_map_ms,readback_ms,path\n";
    for (const Row& r : rows) {
      csv << r.view << ',' << r.mode << ',' << r.threshold << ',' << r.budget << ',' << r.points << ',' << r.nodes << ','
          << r.bytes << ',' << r.cold << ',' << r.warm << ',' << r.psnr << ',' << r.ssim << ',' << r.select_ms << ','
          << r.upload_ms << ',' << r.submit_ms << ',' << r.gpu_draw_ms << ',' << r.gpu_measure_ms << ','
          << r.gpu_tone_map_ms << ',' << r.readback_ms << ',' << r.path << '\n';
    }
  }
  if (!errors) {
    std::printf("data: %s\n", data.c_str());
    return;
  }
  // Per view a colour, per representation a point shape; the x axis of the
  // left panels is points drawn as a share of the view's full-detail frame.
  // The first splat path's rows (the others draw the same points).
  std::vector<std::string> modes;
  for (const Row& r : rows) {
    if (r.mode != "full" && std::find(modes.begin(), modes.end(), r.mode) == modes.end()) modes.push_back(r.mode);
  }
  std::ofstream gp(script);
  gp << "set terminal pngcairo size 1400,1000 font ',11'\nset output '" << png.string() << "'\n"
     << "set datafile separator ','\nset logscale x\nset grid\nset key bottom right\n"
     << "set multiplot layout 2,2 title 'octocosm: level of detail against the reference (all particles, CPU)'\n";
  auto series = [&](int x_column, const char* y_column) {
    std::string plot = "plot ";
    for (std::size_t v = 0; v < views.size(); ++v) {
      const std::string name = "'" + views[v].name + "'";
      double full_points = 0;
      for (const Row& r : rows) {
        if (r.view == views[v].name && r.mode == "full" && r.path == rows.front().path) full_points = static_cast<double>(r.points);
      }
      const std::string x = x_column == 5 ? (full_points > 0 ? "($5 / " + std::to_string(full_points) + ")" : "($5)")
                                          : "($" + std::to_string(x_column) + ")";
      for (std::size_t m = 0; m < modes.size(); ++m) {
        if (plot.size() > 5) plot += ", ";
        plot += "'" + data.string() + "' using (strcol(1) eq " + name + " && strcol(2) eq '" + modes[m] +
                "' && strcol(19) eq '" + rows.front().path + "' ? " + x +
                " : 1/0):" + y_column + " with linespoints pt " + std::to_string(m == 0 ? 7 : 4) + " ps 1.2 lc " +
                std::to_string(v + 1) + " title '" + views[v].name + ", " + modes[m] + "'";
      }
    }
    return plot + "\n";
  };
  gp << "set xlabel 'points drawn / points of the full-detail frame'\nset ylabel 'PSNR (dB)'\n"
     << "set arrow from graph 0, first 40 to graph 1, first 40 nohead dt 2\n" << series(5, "10");
  gp << "set xlabel 'frame time, warm (s)'\n" << series(9, "10");
  gp << "unset arrow\nset ylabel 'SSIM'\nset arrow from graph 0, first 0.98 to graph 1, first 0.98 nohead dt 2\n"
     << "set xlabel 'points drawn / points of the full-detail frame'\n" << series(5, "11");
  gp << "set xlabel 'frame time, warm (s)'\n" << series(9, "11");
  gp << "unset multiplot\n";
  gp.close();
  const std::string command = "gnuplot " + script.string() + " 2>&1";
  if (std::system(command.c_str()) != 0) {
    std::printf("plot: gnuplot failed or is missing (install gnuplot-nox); data in %s, script in %s\n", data.c_str(),
                script.c_str());
  } else {
    std::printf("plot: %s (data %s)\n", png.c_str(), data.c_str());
  }
}

// Playback as the viewer plays: one streamed frame after another (never
// waiting for blocks; parents stand in for children on their way), the
// playhead advancing 1/frames_per_epoch of an epoch a frame, each frame
// measured on the GPU, tone mapped by the newest statistics the GPU has
// finished (the viewer's way), and finished before the next is started
// (the viewer lets the GPU run a frame or two behind). Reports frames per second and how
// many frames drew stand-ins because blocks had not arrived.
void Playback(const Flags& f, SplatPath path) {
  const Dataset dataset = Dataset::Open(f.playback);
  if (dataset.epoch_count() < 2) {
    throw Error::InvalidArgument("--playback: " + f.playback + " holds one epoch; playback needs a series");
  }
  if (f.frames_per_epoch < 1) throw Error::InvalidArgument("--frames-per-epoch must be at least 1");
  const Cube& cube = dataset.cube(0);
  Camera camera;
  camera.position = OverviewPosition(cube, camera.fov_y_degrees);
  camera.look_at = {cube.origin[0] + cube.size / 2, cube.origin[1] + cube.size / 2, cube.origin[2] + cube.size / 2};
  camera.near = cube.size * 1e-4;
  camera.far = 4 * cube.size;
  const RenderView view(camera, f.width, f.height);
  SceneOptions options;
  options.lod.pixel_threshold = f.playback_threshold;
  options.splat_path = path;
  options.compute_radius = f.compute_radius;
  OffscreenRenderer renderer(dataset, ParseHeadlessBackend(f.backend), options);
  std::printf("playback: %s, %u epochs, %dx%d, threshold %g px, %d frames per epoch, %s, splat path %s\n",
              f.playback.c_str(), dataset.epoch_count(), f.width, f.height, f.playback_threshold, f.frames_per_epoch,
              renderer.description().c_str(), SplatPathName(path));
  std::fflush(stdout);
  const int frames = static_cast<int>(dataset.epoch_count() - 1) * f.frames_per_epoch + 1;
  ExposureSmoother smoother;
  double total = 0, worst = 0;
  std::uint64_t points = 0;
  int with_stand_ins = 0;
  for (int frame = 0; frame < frames; ++frame) {
    const double time = static_cast<double>(frame) / f.frames_per_epoch;
    const auto start = std::chrono::steady_clock::now();
    const FrameStats stats = renderer.scene().Stream(view, time, true);
    const ImageStatistics measured = renderer.splat().MeasureLate();
    const double elapsed = frame == 0 ? 0 : 1.0 / 30;  // as if played at 30 frames a second
    const ToneMapSettings settings;
    const double exposure = smoother.Update(AutomaticExposure(settings, measured), elapsed);
    renderer.splat().ToneMapToImage(ResolveToneMap(settings, measured, exposure));
    renderer.splat().Finish();
    const double seconds = Seconds(start);
    total += seconds;
    worst = std::max(worst, seconds);
    points += stats.points_drawn;
    with_stand_ins += stats.stand_ins > 0 || stats.blocks_missing > 0;
  }
  std::printf("playback: %d frames in %.2f s: %.1f frames/s (slowest frame %.3f s), %.0f points a frame, "
              "%d frames drew stand-ins for blocks on their way\n",
              frames, total, frames / total, worst, static_cast<double>(points) / frames, with_stand_ins);
}

// The snapshot measured: the user's, or one generated into the working directory once.
std::string PrepareSnapshot(const Flags& f) {
  const fs::path dir = f.dir;
  if (!f.snapshot.empty()) return f.snapshot;
  if (!fs::exists(dir / "snap" / "snap.0")) {
    synth::ScaleOptions s;
    s.output_directory = (dir / "snap").string();
    s.particle_count = static_cast<std::uint64_t>(f.points);
    s.box_size_mpc_h = f.box;
    const auto start = std::chrono::steady_clock::now();
    synth::RunScaleGenerator(s);
    std::printf("generated %.3g points in %.1f s\n", f.points, Seconds(start));
  }
  return (dir / "snap" / "snap").string();
}

// One store per representation of the inner nodes, ingested once; the
// leaves, and so the views and the full-detail frames, are the same in all.
std::vector<Dataset> PrepareStores(const Flags& f, const std::string& snapshot,
                                   const std::vector<std::string>& representations) {
  if (representations.empty()) throw Error::InvalidArgument("--coarse: name at least one of clusters, round, sample");
  std::vector<Dataset> datasets;
  for (const std::string& representation : representations) {
    if (representation != "clusters" && representation != "round" && representation != "sample") {
      throw Error::InvalidArgument("--coarse: '" + representation + "' is none of clusters, round, sample");
    }
    // "round": the clusters' store, drawn without the clusters' shapes.
    const fs::path store = fs::path(f.dir) / (representation == "sample" ? "store-sample" : "store-clusters");
    if (!fs::exists(store / "manifest.json")) {
      IngestOptions o;
      o.inputs = {snapshot};
      o.output = store.string();
      o.tree.coarse = representation == "sample" ? CoarsePoints::kSample : CoarsePoints::kClusters;
      if (f.capacity > 0) o.tree.capacity = f.capacity;
      o.quiet = true;
      const IngestReport report = Ingest(o);
      std::printf("ingested %llu points (%s) in %.1f s\n", static_cast<unsigned long long>(report.input_points),
                  representation.c_str(), report.seconds);
    }
    datasets.push_back(Dataset::Open(store.string()));
  }
  return datasets;
}

// The reference pictures, rendered once and kept in the working directory;
// `seconds` is the reference's time a view.
std::vector<HdrImage> PrepareReferences(const Flags& f, const std::string& snapshot, const std::vector<NamedView>& views,
                                        const std::vector<RenderView>& render_views, double& seconds) {
  const fs::path dir = f.dir;
  std::vector<HdrImage> references(views.size());
  if (!f.reference) return references;
  bool missing = false;
  for (std::size_t v = 0; v < views.size(); ++v) missing |= !fs::exists(dir / ("reference-" + views[v].name + ".pfm"));
  if (missing) {
    ReferenceRenderOptions options;
    options.threads = f.threads;
    ReferenceRenderStats stats;
    references = RenderReference(snapshot, render_views, options, &stats);
    seconds = stats.seconds / static_cast<double>(views.size());
    std::ofstream(dir / "reference-seconds.txt") << seconds << "\n";
    for (std::size_t v = 0; v < views.size(); ++v) WritePfm((dir / ("reference-" + views[v].name + ".pfm")).string(), references[v]);
  } else {
    for (std::size_t v = 0; v < views.size(); ++v) references[v] = ReadPfm((dir / ("reference-" + views[v].name + ".pfm")).string());
    std::ifstream(dir / "reference-seconds.txt") >> seconds;
  }
  return references;
}

// Every view at full detail (unless --no-full) and at each representation,
// threshold and budget of the sweep, against its reference.
std::vector<Row> Sweep(const Flags& f, const std::vector<Dataset>& datasets, const std::vector<std::string>& representations,
                       const std::vector<NamedView>& views, const std::vector<RenderView>& render_views,
                       const std::vector<HdrImage>& references, HeadlessBackend backend) {
  std::printf("\n%-9s %-12s %9s %10s %11s %7s %10s %9s %9s %7s %7s %7s %7s %7s %8s %7s %7s %7s %-7s\n", "view", "mode",
              "threshold", "budget", "points", "nodes", "read", "cold s", "warm s", "PSNR", "SSIM", "sel ms", "upl ms",
              "call ms", "gpu draw", "measure", "tone", "read ms", "path");
  std::vector<SplatPath> paths;
  for (const std::string& p : Split(f.splat)) paths.push_back(ParseSplatPath(p));
  if (paths.empty()) throw Error::InvalidArgument("--splat names no path");
  std::vector<Row> rows;
  const std::vector<std::string> thresholds = Split(f.thresholds), budgets = Split(f.budgets);
  for (std::size_t v = 0; v < views.size(); ++v) {
    // Without a reference (--no-reference) the tone map is fixed by an
    // exposure of 1 and the error columns stay 0.
    ToneMapParameters tone;
    tone.exposure = 1;
    tone.floor = 1e-4;
    DisplayImage reference;
    if (f.reference) {
      tone = ResolveToneMap({}, MeasureImage(references[v], ColorMode::kDensity));
      reference = ToneMap(references[v], tone);
      WritePng((fs::path(f.dir) / ("reference-" + views[v].name + ".png")).string(), ToBytes(reference));
    }
    if (f.full) {
      SceneOptions options;
      options.lod.pixel_threshold = 1e-9;
      options.gpu_cache_bytes = std::size_t{64} << 30;
      const fs::path save_as = f.save_pictures ? fs::path(f.dir) / ("picture-" + views[v].name + "-full.pfm") : fs::path();
      for (Row& row : Measure(datasets.front(), options, render_views[v], backend, tone, reference, paths, f.compute_radius,
                              save_as)) {
        row.view = views[v].name;
        row.mode = "full";
        rows.push_back(row);
        PrintRow(row);
      }
    }
    for (std::size_t r = 0; r < representations.size(); ++r) {
      for (const std::string& t : thresholds) {
        for (const std::string& b : budgets) {
          SceneOptions options;
          options.lod.pixel_threshold = std::stod(t);
          options.lod.point_budget = static_cast<std::uint64_t>(std::stod(b));
          options.cluster_shapes = representations[r] != "round";
          const fs::path save_as = f.save_pictures ? fs::path(f.dir) / ("picture-" + views[v].name + "-" + representations[r] +
                                                                        "-t" + t + "-b" + b + ".pfm")
                                                   : fs::path();
          for (Row& row : Measure(datasets[r], options, render_views[v], backend, tone, reference, paths, f.compute_radius,
                                  save_as)) {
            row.view = views[v].name;
            row.mode = representations[r];
            row.threshold = options.lod.pixel_threshold;
            row.budget = options.lod.point_budget;
            rows.push_back(row);
            PrintRow(row);
          }
        }
      }
      // Cluster by cluster: the mode "<representation>-cut", its threshold
      // the cluster error.
      const bool linked = (datasets[r].cluster_columns() & kClusterLinkColumns) == kClusterLinkColumns;
      for (const std::string& e : linked ? Split(f.cluster_errors) : std::vector<std::string>{}) {
        for (const std::string& b : budgets) {
          SceneOptions options;
          options.cluster_error = std::stod(e);
          options.lod.point_budget = static_cast<std::uint64_t>(std::stod(b));
          options.cluster_shapes = representations[r] != "round";
          const std::string mode = representations[r] + "-cut";
          const fs::path save_as = f.save_pictures ? fs::path(f.dir) / ("picture-" + views[v].name + "-" + mode + "-e" + e +
                                                                        "-b" + b + ".pfm")
                                                   : fs::path();
          for (Row& row : Measure(datasets[r], options, render_views[v], backend, tone, reference, paths, f.compute_radius,
                                  save_as)) {
            row.view = views[v].name;
            row.mode = mode;
            row.threshold = options.cluster_error;
            row.budget = options.lod.point_budget;
            rows.push_back(row);
            PrintRow(row);
          }
        }
      }
    }
  }
  return rows;
}

// Per view and representation, the fastest level of detail that meets the
// quality targets, and its ratios to the full rendering and the reference.
void PrintTargets(const std::vector<Row>& rows, const std::vector<NamedView>& views,
                  const std::vector<std::string>& representations, double reference_seconds) {
  std::printf("\nreference: %.1f s a view (CPU, all points, double precision)\n", reference_seconds);
  std::printf("targets: PSNR >= 40 dB and SSIM >= 0.98 at >= 20x less time than the full rendering\n");
  std::vector<std::string> paths;
  for (const Row& r : rows) {
    if (std::find(paths.begin(), paths.end(), r.path) == paths.end()) paths.push_back(r.path);
  }
  for (const NamedView& v : views) {
    for (const std::string& representation : representations) {
      for (const std::string& path : paths) {
        const Row* full = nullptr;
        const Row* best = nullptr;  // fastest LOD row meeting the quality targets
        for (const Row& r : rows) {
          if (r.view != v.name || r.path != path) continue;
          if (r.mode == "full") full = &r;
          if (r.mode == representation && r.psnr >= 40 && r.ssim >= 0.98 && (!best || r.warm < best->warm)) best = &r;
        }
        if (!best) {
          std::printf("  %-9s %-8s %-7s no level of detail in the sweep meets PSNR 40 dB and SSIM 0.98\n", v.name.c_str(),
                      representation.c_str(), path.c_str());
          continue;
        }
        std::printf("  %-9s %-8s %-7s threshold %g, budget %llu: PSNR %.1f dB, SSIM %.4f, %llu points", v.name.c_str(),
                    representation.c_str(), path.c_str(), best->threshold, static_cast<unsigned long long>(best->budget),
                    best->psnr, best->ssim, static_cast<unsigned long long>(best->points));
        if (full) {
          std::printf(" (%.1f%% of full detail's), %.3f s warm: %.1fx less than the full GPU rendering (%.2f s)",
                      100.0 * static_cast<double>(best->points) / static_cast<double>(std::max<std::uint64_t>(full->points, 1)),
                      best->warm, full->warm / best->warm, full->warm);
        }
        std::printf(", %.0fx less than the reference\n", reference_seconds / best->warm);
      }
    }
  }
}

// How much of a view's full-detail frame a level of detail can leave out
// without coarsening what a pixel shows: the share of its points in leaves
// whose points lie at most 1, 2, 4, 8 pixels apart on the screen.
void PrintFullDetailSpacing(const Dataset& dataset, const NamedView& named_view, const RenderView& view) {
  const NodeHierarchy hierarchy = NodeHierarchy::Load(dataset, 0);
  const ScreenErrorView error_view{view.camera(), static_cast<double>(view.height()), 1e-9};
  LodOptions lod;
  lod.pixel_threshold = error_view.threshold_pixels;
  const LodFrontier full = SelectLodFrontier(hierarchy, dataset.cube(0), error_view, lod);
  const ScreenErrorMeter spacing(error_view);
  const double limits[] = {1, 2, 4, 8};
  double within[4] = {0, 0, 0, 0};
  for (const std::int32_t n : full.selected) {
    const NodeHierarchy::Node& node = hierarchy.node(n);
    const double pixels = spacing(dataset.cube(0).NodeCubeOf(node.key), node.entry.point_count);
    for (int k = 0; k < 4; ++k) within[k] += pixels <= limits[k] ? static_cast<double>(node.entry.point_count) : 0.0;
  }
  const double total = std::max(1.0, static_cast<double>(full.points));
  std::printf("%s: full detail %llu points in view; in leaves whose points lie at most 1 / 2 / 4 / 8 px apart: "
              "%.0f%% / %.0f%% / %.0f%% / %.0f%%\n",
              named_view.name.c_str(), static_cast<unsigned long long>(full.points), 100 * within[0] / total,
              100 * within[1] / total, 100 * within[2] / total, 100 * within[3] / total);
}

// The reference's mass per pixel blurred by a Gaussian of `sigma` pixels
// (separable, to 4 sigma; mass beyond the image's edges is lost).
HdrImage BlurMass(const HdrImage& image, double sigma) {
  const int radius = static_cast<int>(std::ceil(4 * sigma));
  std::vector<double> weights(static_cast<std::size_t>(2 * radius + 1));
  double sum = 0;
  for (int k = -radius; k <= radius; ++k) {
    sum += weights[static_cast<std::size_t>(k + radius)] = std::exp(-0.5 * k * k / (sigma * sigma));
  }
  for (double& w : weights) w /= sum;
  const int width = image.width, height = image.height;
  const auto pixel = [width](int i, int j) { return static_cast<std::size_t>(j) * static_cast<std::size_t>(width) + i; };
  std::vector<double> along_rows(pixel(0, height), 0.0);
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      double m = 0;
      for (int k = std::max(-radius, -i); k <= radius && i + k < width; ++k) {
        m += weights[static_cast<std::size_t>(k + radius)] * image.at(i + k, j, 0);
      }
      along_rows[pixel(i, j)] = m;
    }
  }
  HdrImage out = image;
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      double m = 0;
      for (int k = std::max(-radius, -j); k <= radius && j + k < height; ++k) {
        m += weights[static_cast<std::size_t>(k + radius)] * along_rows[pixel(i, j + k)];
      }
      out.rgba[4 * pixel(i, j)] = m;
    }
  }
  return out;
}

// How sharp a level of detail must be to meet the target in this view: the
// PSNR and SSIM of the reference itself, blurred by a Gaussian of 0.5 to 2
// pixels, against the reference. Blobs that move or spread mass by about a
// pixel cannot do better than the column of that width.
void PrintSharpnessScale(const NamedView& named_view, const HdrImage& reference) {
  const ToneMapParameters tone = ResolveToneMap({}, MeasureImage(reference, ColorMode::kDensity));
  const DisplayImage sharp = ToneMap(reference, tone);
  std::printf("%s: the reference blurred by sigma = 0.5 / 0.75 / 1 / 1.5 / 2 px:", named_view.name.c_str());
  for (double sigma : {0.5, 0.75, 1.0, 1.5, 2.0}) {
    const DisplayImage blurred = ToneMap(BlurMass(reference, sigma), tone);
    std::printf(" %.1f dB / %.4f%s", Psnr(blurred, sharp), Ssim(blurred, sharp), sigma < 2 ? "," : "\n");
  }
}

// The selection's cost: the same frame with 10^6 IDs highlighted.
void MeasureSelection(const Dataset& dataset, const NamedView& named_view, const RenderView& view,
                      HeadlessBackend backend) {
  std::vector<std::uint64_t> ids;
  for (std::uint64_t id = 1; ids.size() < 1000000; id += 2) ids.push_back(id);
  SceneOptions options;
  options.lod.pixel_threshold = 1;
  OffscreenRenderer renderer(dataset, backend, options);
  renderer.Render(view, 0, {}, false);
  const double plain = renderer.Render(view, 0, {}, false).frame_seconds;
  renderer.scene().SetSelection(ids);
  const Picture first = renderer.Render(view, 0, {}, false);  // looks the IDs up through the ID index
  const double selected = renderer.Render(view, 0, {}, false).frame_seconds;
  std::printf("selection: %s, threshold 1: %.3f s without, %.3f s with 10^6 IDs (%+.1f%%; %llu of them in the store, "
              "drawn at full detail; the first frame, which looks them up, %.3f s)\n",
              named_view.name.c_str(), plain, selected, 100 * (selected / plain - 1),
              static_cast<unsigned long long>(first.stats.points_highlighted), first.frame_seconds);
}

void Run(const Flags& f) {
  if (!f.playback.empty()) {
    for (const std::string& path : Split(f.splat)) Playback(f, ParseSplatPath(path));
    return;
  }
  fs::create_directories(f.dir);
  const HeadlessBackend backend = ParseHeadlessBackend(f.backend);
  const std::string snapshot = PrepareSnapshot(f);
  const std::vector<std::string> representations = Split(f.coarse);
  const std::vector<Dataset> datasets = PrepareStores(f, snapshot, representations);
  const std::vector<NamedView> views = Views(datasets.front(), Split(f.views));
  std::vector<RenderView> render_views;
  for (const NamedView& v : views) {
    render_views.emplace_back(v.camera, f.width, f.height);
    PrintCameraFlags(v);
  }
  double reference_seconds = 0;
  const std::vector<HdrImage> references = PrepareReferences(f, snapshot, views, render_views, reference_seconds);
  if (f.reference) {
    std::printf("reference: %llu points, %.1f s a view on the CPU\n",
                static_cast<unsigned long long>(datasets.front().points(0)), reference_seconds);
  }
  if (f.prepare_only) return;
  for (std::size_t v = 0; v < views.size(); ++v) {
    PrintFullDetailSpacing(datasets.front(), views[v], render_views[v]);
    if (f.reference) PrintSharpnessScale(views[v], references[v]);
  }

  const std::vector<Row> rows = Sweep(f, datasets, representations, views, render_views, references, backend);
  std::vector<std::string> modes = representations;
  for (const Row& r : rows) {
    if (r.mode != "full" && std::find(modes.begin(), modes.end(), r.mode) == modes.end()) modes.push_back(r.mode);
  }
  if (f.reference) PrintTargets(rows, views, modes, reference_seconds);
  Plot(fs::path(f.dir), rows, views, f.reference);
  if (f.selection) MeasureSelection(datasets.front(), views[0], render_views[0], backend);
}

}  // namespace
}  // namespace octocosm

int main(int argc, char** argv) {
  octocosm::Flags f;
  CLI::App app{"octocosm-bench-render: frame time, bytes read, PSNR and SSIM of levels of detail against the reference"};
  app.add_option("--dir", f.dir, "working directory: generated snapshot, store, reference images, results (reused)");
  app.add_option("--points", f.points, "particles of the generated set")->default_val(1e8);
  app.add_option("--box", f.box, "box side of the generated set, Mpc/h")->default_val(500);
  app.add_option("--width", f.width, "image width")->default_val(1280);
  app.add_option("--height", f.height, "image height")->default_val(720);
  app.add_option("--thresholds", f.thresholds, "pixel thresholds of the sweep")->default_val("8,4,2,1,0.5");
  app.add_option("--budgets", f.budgets, "point budgets of the sweep (0: none)")->default_val("0,1e6,4e6");
  app.add_option("--cluster-errors", f.cluster_errors,
                 "also sweep the level of detail cluster by cluster with these cluster errors (mean particle masses; "
                 "the mode <coarse>-cut, on stores that link their clusters)");
  app.add_option("--views", f.views, "views: overview, mid, deep")->default_val("overview,mid,deep");
  app.add_option("--coarse", f.coarse,
                 "inner nodes' representations to compare: clusters, round (the clusters drawn without their shapes), sample")
      ->default_val("clusters,sample");
  app.add_option("--snapshot", f.snapshot,
                 "measure on this snapshot (any format ingest reads, first epoch) instead of a generated one");
  app.add_option("--capacity", f.capacity, "points a node holds in the stores (default: ingest's)");
  app.add_option("--backend", f.backend, "osmesa or egl")->default_val("osmesa");
  app.add_option("--threads", f.threads, "threads of the reference renderer (default: all)");
  app.add_option("--splat", f.splat,
                 "splat paths to time, comma-separated: raster, compute, auto (the first cold and warm, the others warm "
                 "on the same blocks; --playback plays through each)")
      ->default_val("auto");
  app.add_option("--compute-radius", f.compute_radius, "compute path: blobs up to this radius (pixels) are added by one thread, larger ones by a workgroup")
      ->default_val(4);
  app.add_flag("!--no-reference", f.reference,
               "time only: no reference rendering (minutes on the CPU at 10^8 points), no PSNR or SSIM columns (0)");
  app.add_flag("!--no-full", f.full, "skip the full-detail GPU rendering");
  app.add_flag("--save-pictures", f.save_pictures,
               "write each frame's accumulation (mass per pixel) into --dir as picture-VIEW-MODE-tT-bB.pfm, "
               "to compare with reference-VIEW.pfm");
  app.add_flag("--selection", f.selection, "also time a frame with 10^6 selected IDs");
  app.add_option("--playback", f.playback, "measure playback through the epochs of this store instead (frames per second)");
  app.add_option("--playback-threshold", f.playback_threshold, "pixel threshold of --playback")->default_val(1);
  app.add_option("--frames-per-epoch", f.frames_per_epoch, "frames between two epochs in --playback")->default_val(30);
  app.add_flag("--prepare-only", f.prepare_only, "generate, ingest and render the references, then stop (no timings)");
  CLI11_PARSE(app, argc, argv);
  try {
    octocosm::Run(f);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "octocosm-bench-render: %s\n", e.what());
    return 1;
  }
  return 0;
}
