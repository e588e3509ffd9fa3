// octocosm-bench-remote: a store rendered along camera paths from its
// directory and from nginx through a throttled link (bench/throttled_proxy.h:
// a round trip and a bandwidth per client, a trunk shared by all), as a user
// on a desktop reads a store from a central server (docs/REMOTE.md).
//
//   single client   the same path from the directory and from the URL, each
//                   twice: a first pass that fetches as the camera moves, and
//                   a second once the caches are warm; frames per second,
//                   bytes fetched per frame, the time to open the store and
//                   draw its first frame, and to draw a new view.
//   follow          --follow IDs (taken from a sphere at the first epoch's
//                   centre) through every epoch, as `octocosm follow` finds
//                   them, from the directory and from the URL, each store
//                   opened afresh.
//   query           every point of a box an eighth of the cube wide at the
//                   first epoch's centre, at full detail (as `octocosm
//                   query --box`), from the directory and from the URL, each
//                   store opened afresh.
//   many clients    --clients processes, each its own path and link, all at
//                   once against one nginx; each one's rate against one
//                   client's alone (measured the same way just before), and
//                   nginx's CPU time per client. With --fetch-only the
//                   clients fetch each frame's blocks as the renderer would
//                   (the same level of detail, columns, cache and
//                   prefetcher) without drawing them: on a machine with
//                   fewer cores than clients, the server's and the link's
//                   share of the rate rather than the renderers'.
//
// nginx (Debian's nginx-light) must be installed; the bench starts and stops
// its own on a free port.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <numbers>
#include <numeric>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "bench/throttled_proxy.h"
#include "index/block_codec.h"
#include "index/dataset.h"
#include "index/node_hierarchy.h"
#include "query/column_reader.h"
#include "query/lod_frontier.h"
#include "query/particle_lookup.h"
#include "query/query.h"
#include "query/region.h"
#include "render/gl_context.h"
#include "render/offscreen_renderer.h"
#include "storage/block_cache.h"
#include "storage/prefetcher.h"
#include "tests/support/nginx_server.h"
#include "tools/cli_util.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using testing_support::NginxServer;

double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

struct Flags {
  std::string store;
  int frames = 40;
  double rtt_ms = 20;
  std::string rate = "100M";
  std::string shared_rate = "800M";
  int clients = 8;
  int width = 640, height = 360;
  double error = 2;
  double cluster_error = 0;  // > 0: the cut cluster by cluster (drawing only)
  std::string backend = "osmesa";
  int follow = 100;
  bool query = true;
  bool each_alone = false;  // also render the remote path with every block read alone
  bool fetch_only = false;  // many clients fetch their frames' blocks without drawing them
  // Client mode (the bench starts itself so): render this URL's path `variant`.
  std::string client_url;
  int variant = 0;
};

// Path `variant` of `frames` frames: the camera circles the cube's centre
// inside the box, each variant starting at another angle.
Camera PathCamera(const Cube& cube, int variant, int frame, int frames, double aspect) {
  const double s = cube.size;
  const std::array<double, 3> centre = {cube.origin[0] + s / 2, cube.origin[1] + s / 2, cube.origin[2] + s / 2};
  const double angle = variant * std::numbers::pi / 4 + 0.6 * frame / std::max(1, frames - 1);
  Camera camera;
  camera.position = {centre[0] + 0.45 * s * std::cos(angle), centre[1] + 0.1 * s * std::sin(3 * angle),
                     centre[2] + 0.45 * s * std::sin(angle)};
  camera.look_at = centre;
  camera.aspect = aspect;
  camera.near = s * 1e-4;
  camera.far = 4 * s;
  return camera;
}

struct PathRun {
  double open_and_first_s = 0;  // opening the store and drawing the first frame
  double first_pass_fps = 0;    // the other frames, fetching as the camera moves
  double warm_fps = 0;          // the path again
  double new_view_s = 0;        // a frame of another path's view, after the two passes
  int frames = 0;
};

// Times a camera path drawn by frame(path, k), which `start`ed by opening
// the store: its first frame, two passes over the others (the first
// fetching, the second warm), and a frame of another path's view.
template <typename Frame>
PathRun TimePath(const Flags& f, int variant, Clock::time_point start, const Frame& frame) {
  PathRun run;
  run.frames = f.frames;
  frame(variant, 0);
  run.open_and_first_s = Seconds(start);
  for (int pass = 0; pass < 2; ++pass) {
    const auto pass_start = Clock::now();
    for (int k = 1; k < f.frames; ++k) frame(variant, k);
    const double fps = (f.frames - 1) / std::max(1e-9, Seconds(pass_start));
    (pass == 0 ? run.first_pass_fps : run.warm_fps) = fps;
  }
  const auto new_view = Clock::now();
  frame(variant + 4, f.frames / 2);
  run.new_view_s = Seconds(new_view);
  return run;
}

PathRun RenderPath(const std::string& store, const Flags& f, int variant, bool coalesce_reads = true) {
  const auto start = Clock::now();
  const Dataset dataset = Dataset::Open(store);
  if (f.cluster_error > 0 && (dataset.cluster_columns() & kClusterLinkColumns) != kClusterLinkColumns) {
    throw Error::InvalidArgument("--cluster-error: the store " + store + " does not link its clusters to their "
                                 "children's points; use --error");
  }
  SceneOptions options;
  options.lod.pixel_threshold = f.error;
  options.cluster_error = f.cluster_error;
  options.coalesce_reads = coalesce_reads;
  OffscreenRenderer renderer(dataset, ParseHeadlessBackend(f.backend), options);
  const Cube& cube = dataset.cube(0);
  const double aspect = static_cast<double>(f.width) / f.height;
  const ToneMapSettings tone;
  const auto frame = [&](int variant_k, int k) {
    renderer.Render(RenderView(PathCamera(cube, variant_k, k, f.frames, aspect), f.width, f.height), 0, tone, false);
  };
  return TimePath(f, variant, start, frame);
}

// RenderPath's frames without drawing: each frame's level of detail is
// selected as the renderer selects it and its blocks fetched as the
// renderer fetches a complete frame's (the columns a density picture of
// clusters with shapes reads, a 1 GiB cache, 32 reads in flight from a
// server: render/scene_renderer.cc), every one waited for.
PathRun FetchPath(const std::string& store, const Flags& f, int variant) {
  const auto start = Clock::now();
  const Dataset dataset = Dataset::Open(store);
  const NodeHierarchy hierarchy = NodeHierarchy::Load(dataset, 0);
  const ColumnSet columns = (ColumnBit(ColumnId::kPosition) | ColumnBit(ColumnId::kWeight) |
                             ColumnBit(ColumnId::kSmoothing) | ColumnBit(ColumnId::kType) |
                             (dataset.columns() & ColumnBit(ColumnId::kShape)));
  ColumnSubsetSource source(dataset, columns);
  BlockCache cache(&source, std::size_t{1} << 30);
  Prefetcher::Options prefetch;
  prefetch.workers = dataset.store().page_file(0).remote() ? 32 : 2;
  Prefetcher prefetcher(cache, prefetch);
  const Cube& cube = dataset.cube(0);
  const double aspect = static_cast<double>(f.width) / f.height;
  LodOptions lod;
  lod.pixel_threshold = f.error;
  const auto frame = [&](int variant_k, int k) {
    const RenderView view(PathCamera(cube, variant_k, k, f.frames, aspect), f.width, f.height);
    const LodFrontier frontier =
        SelectLodFrontier(hierarchy, cube, {view.camera(), static_cast<double>(view.height()), f.error}, lod);
    std::vector<BlockId> wanted;
    for (const std::int32_t node : frontier.selected) wanted.push_back({0, hierarchy.node(node).key.value()});
    prefetcher.Submit(wanted);
    prefetcher.Drain();
    for (const BlockId& id : wanted) {
      if (cache.TryGet(id)) continue;
      if (const std::optional<Error> error = prefetcher.LastError(id)) throw *error;
      cache.Get(id);  // evicted meanwhile: read it here
    }
  };
  return TimePath(f, variant, start, frame);
}

std::string StoreUrl(int port, const Flags& f) {
  return "http://127.0.0.1:" + std::to_string(port) + "/" + fs::path(f.store).filename().string();
}

// Clients as processes of this program, all started before any is waited for.
std::vector<PathRun> RunClients(const Flags& f, int count, NginxServer& nginx, double rate,
                                const std::shared_ptr<PacedLink>& trunk, std::uint64_t& bytes, std::uint64_t& requests) {
  std::vector<std::unique_ptr<ThrottledProxy>> proxies;
  std::vector<FILE*> pipes;
  const std::string self = fs::read_symlink("/proc/self/exe").string();
  for (int c = 0; c < count; ++c) {
    proxies.push_back(std::make_unique<ThrottledProxy>(nginx.port(), f.rtt_ms / 1e3, rate, trunk));
    std::ostringstream command;
    command << self << " --client " << StoreUrl(proxies.back()->port(), f) << " --variant " << c << " --frames "
            << f.frames << " --width " << f.width << " --height " << f.height << " --error " << f.error
            << " --cluster-error " << f.cluster_error << " --backend " << f.backend
            << (f.fetch_only ? " --fetch-only" : "") << " x";
    pipes.push_back(::popen(command.str().c_str(), "r"));
  }
  std::vector<PathRun> runs;
  for (int c = 0; c < count; ++c) {
    PathRun run;
    char line[512] = {};
    if (pipes[c] == nullptr || std::fgets(line, sizeof line, pipes[c]) == nullptr ||
        std::sscanf(line, "client %lf %lf %lf %lf", &run.open_and_first_s, &run.first_pass_fps, &run.warm_fps,
                    &run.new_view_s) != 4) {
      throw Error::Io("client " + std::to_string(c), "no result (its output: " + std::string(line) + ")");
    }
    if (::pclose(pipes[c]) != 0) throw Error::Io("client " + std::to_string(c), "failed");
    runs.push_back(run);
  }
  bytes = 0;
  requests = 0;
  for (const auto& proxy : proxies) {
    bytes += proxy->bytes_to_client();
    requests += proxy->requests();
  }
  return runs;
}

// User and system CPU seconds of this process (RUSAGE_SELF) or of its
// children waited for (RUSAGE_CHILDREN).
double CpuSeconds(int who) {
  rusage usage{};
  ::getrusage(who, &usage);
  const auto seconds = [](const timeval& t) { return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec); };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

// CPU seconds of nginx's processes (its master and workers) so far.
double NginxCpuSeconds(const fs::path& work) {
  const std::string master = testing_support::ReadText(work / "nginx.pid");
  const long ticks = ::sysconf(_SC_CLK_TCK);
  double seconds = 0;
  for (const auto& entry : fs::directory_iterator("/proc")) {
    const std::string name = entry.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;  // not a process
    std::ifstream stat(entry.path() / "stat");
    std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
    const std::size_t close = text.rfind(')');
    if (close == std::string::npos) continue;
    std::istringstream fields(text.substr(close + 2));
    std::string state, ppid, skip;
    fields >> state >> ppid;
    const std::string pid = entry.path().filename().string();
    if (pid != std::to_string(std::atoi(master.c_str())) && ppid != std::to_string(std::atoi(master.c_str()))) continue;
    for (int i = 0; i < 9; ++i) fields >> skip;  // to utime (field 14)
    double utime = 0, stime = 0;
    fields >> utime >> stime;
    seconds += (utime + stime) / static_cast<double>(ticks);
  }
  return seconds;
}

// Up to `count` IDs of particles near the centre of epoch 0's cube.
std::vector<std::uint64_t> IdsToFollow(const Dataset& dataset, int count) {
  const Cube& cube = dataset.cube(0);
  const std::array<double, 3> centre = {cube.origin[0] + cube.size / 2, cube.origin[1] + cube.size / 2,
                                        cube.origin[2] + cube.size / 2};
  const std::unique_ptr<Region> sphere = MakeSphereRegion(centre, cube.size / 8, cube);
  return ParticleIdsInRegion(dataset, 0, *sphere, static_cast<std::size_t>(count)).ids;
}

struct FollowRun {
  double seconds = 0;  // opening the store and finding every ID in every epoch
  std::size_t found = 0;
  std::uint64_t blocks = 0;
};

FollowRun Follow(const std::string& store, std::span<const std::uint64_t> ids) {
  const auto start = Clock::now();
  const Dataset dataset = Dataset::Open(store);
  ParticleLocator locator(dataset);
  std::vector<std::uint32_t> epochs(dataset.epoch_count());
  std::iota(epochs.begin(), epochs.end(), 0u);
  FollowRun run;
  for (const auto& states : locator.FindInEpochs(epochs, ids, true)) {
    for (const auto& state : states) run.found += state.has_value();
  }
  run.seconds = Seconds(start);
  run.blocks = locator.reads().blocks;
  return run;
}

struct QueryRun {
  double seconds = 0;  // opening the store and reading every point of the box
  std::uint64_t points = 0;
  std::uint64_t blocks = 0;
};

QueryRun QueryBox(const std::string& store) {
  const auto start = Clock::now();
  const Dataset dataset = Dataset::Open(store);
  const Cube& cube = dataset.cube(0);
  std::array<double, 3> lo, hi;
  for (int a = 0; a < 3; ++a) {
    lo[a] = cube.origin[a] + cube.size * (0.5 - 1.0 / 16);
    hi[a] = cube.origin[a] + cube.size * (0.5 + 1.0 / 16);
  }
  const std::unique_ptr<Region> box = MakeBoxRegion(lo, hi, cube);
  QueryOptions options;
  options.level = kMaxLevel;
  QueryRun run;
  const QueryStats stats = RunQuery(dataset, *box, options, [&](const QueryBatch& batch) { run.points += batch.count; });
  run.seconds = Seconds(start);
  run.blocks = stats.reads.blocks;
  return run;
}

// A request and byte count of 0 prints nothing in their columns (a local run).
void PrintRun(const char* what, const PathRun& r, double bytes_per_frame, double requests_per_frame = 0) {
  std::printf("%-28s %10.2f %10.2f %10.2f %10.3f", what, r.open_and_first_s, r.first_pass_fps, r.warm_fps, r.new_view_s);
  if (bytes_per_frame > 0) std::printf(" %14.0f", bytes_per_frame);
  if (requests_per_frame > 0) std::printf(" %14.1f", requests_per_frame);
  std::printf("\n");
}

void Coordinate(const Flags& f) {
  const double rate = static_cast<double>(ParseByteSize(f.rate, "--rate"));
  const double shared_rate = static_cast<double>(ParseByteSize(f.shared_rate, "--shared-rate"));
  const fs::path work = fs::temp_directory_path() / ("octocosm-bench-remote-" + std::to_string(::getpid()));
  // nginx's configuration and logs, removed once it has stopped (declared
  // first, destroyed last).
  struct RemovedAtEnd {
    fs::path path;
    ~RemovedAtEnd() {
      std::error_code ignored;
      fs::remove_all(path, ignored);
    }
  } work_removed{work};
  NginxServer nginx(fs::absolute(f.store).parent_path(), work / "nginx");
  if (!nginx.started()) throw Error::Io("nginx", nginx.error());
  std::printf("store %s, %d frames a path at %dx%d, %s %g; link: %.0f ms round trip, %s/s a client, %s/s shared\n",
              f.store.c_str(), f.frames, f.width, f.height, f.cluster_error > 0 ? "cluster error" : "threshold (px)",
              f.cluster_error > 0 ? f.cluster_error : f.error, f.rtt_ms, f.rate.c_str(), f.shared_rate.c_str());
  std::printf("%-28s %10s %10s %10s %10s %14s %14s\n", "", "open+1st s", "pass 1 f/s", "warm f/s", "new view s",
              "bytes/frame", "requests/frame");

  const PathRun local = RenderPath(f.store, f, 0);
  PrintRun("local directory", local, 0);
  std::fflush(stdout);
  for (const bool coalesce : {true, false}) {
    if (!coalesce && !f.each_alone) break;
    auto trunk = std::make_shared<PacedLink>(shared_rate);
    ThrottledProxy proxy(nginx.port(), f.rtt_ms / 1e3, rate, trunk);
    const PathRun remote = RenderPath(StoreUrl(proxy.port(), f), f, 0, coalesce);
    const double frames = 2.0 * f.frames + 1;
    PrintRun(coalesce ? "remote, this process" : "remote, each block alone", remote,
             static_cast<double>(proxy.bytes_to_client()) / frames, static_cast<double>(proxy.requests()) / frames);
    std::printf("remote / local: pass 1 %.2f, warm %.2f, first frame %.2f, new view %.2f\n",
                remote.first_pass_fps / local.first_pass_fps, remote.warm_fps / local.warm_fps,
                remote.open_and_first_s / local.open_and_first_s, remote.new_view_s / local.new_view_s);
    std::fflush(stdout);
  }
  std::fflush(stdout);

  if (f.query) {
    const QueryRun local_query = QueryBox(f.store);
    auto trunk = std::make_shared<PacedLink>(shared_rate);
    ThrottledProxy proxy(nginx.port(), f.rtt_ms / 1e3, rate, trunk);
    const QueryRun remote_query = QueryBox(StoreUrl(proxy.port(), f));
    std::printf("query a box of 1/512 of the cube at full detail (%llu points, %llu blocks): local %.3f s, remote "
                "%.3f s (%.1f round trips), %.1f MB fetched\n",
                static_cast<unsigned long long>(remote_query.points), static_cast<unsigned long long>(remote_query.blocks),
                local_query.seconds, remote_query.seconds, remote_query.seconds / (f.rtt_ms / 1e3),
                static_cast<double>(proxy.bytes_to_client()) / 1e6);
    std::fflush(stdout);
  }

  const Dataset local_dataset = Dataset::Open(f.store);
  if (f.follow > 0 && local_dataset.has_id_index()) {
    const std::vector<std::uint64_t> ids = IdsToFollow(local_dataset, f.follow);
    const FollowRun local_follow = Follow(f.store, ids);
    auto trunk = std::make_shared<PacedLink>(shared_rate);
    ThrottledProxy proxy(nginx.port(), f.rtt_ms / 1e3, rate, trunk);
    const FollowRun remote_follow = Follow(StoreUrl(proxy.port(), f), ids);
    std::printf("follow %zu IDs through %u epochs (%zu found, %llu leaves read): local %.3f s, remote %.3f s "
                "(%.1f round trips), %.1f MB fetched\n",
                ids.size(), local_dataset.epoch_count(), remote_follow.found,
                static_cast<unsigned long long>(remote_follow.blocks), local_follow.seconds, remote_follow.seconds,
                remote_follow.seconds / (f.rtt_ms / 1e3), static_cast<double>(proxy.bytes_to_client()) / 1e6);
    std::fflush(stdout);
  }

  if (f.clients < 1) return;
  auto trunk = std::make_shared<PacedLink>(shared_rate);
  std::uint64_t bytes = 0, requests = 0;
  const double frames = 2.0 * f.frames + 1;
  const std::vector<PathRun> alone = RunClients(f, 1, nginx, rate, trunk, bytes, requests);
  PrintRun("one client process", alone[0], static_cast<double>(bytes) / frames, static_cast<double>(requests) / frames);
  const double cpu_before = NginxCpuSeconds(work / "nginx");
  const double clients_before = CpuSeconds(RUSAGE_CHILDREN), proxies_before = CpuSeconds(RUSAGE_SELF);
  const auto start = Clock::now();
  const std::vector<PathRun> many = RunClients(f, f.clients, nginx, rate, trunk, bytes, requests);
  const double wall = Seconds(start);
  const double cpu = NginxCpuSeconds(work / "nginx") - cpu_before;
  const double clients_cpu = CpuSeconds(RUSAGE_CHILDREN) - clients_before;
  const double proxies_cpu = CpuSeconds(RUSAGE_SELF) - proxies_before;
  double worst = 1e300;
  for (std::size_t c = 0; c < many.size(); ++c) {
    PrintRun(("client " + std::to_string(c) + " of " + std::to_string(f.clients)).c_str(), many[c],
             static_cast<double>(bytes) / static_cast<double>(many.size()) / frames,
             static_cast<double>(requests) / static_cast<double>(many.size()) / frames);
    worst = std::min(worst, many[c].first_pass_fps / alone[0].first_pass_fps);
  }
  std::printf("%d clients%s: the slowest at %.2f of one client's pass-1 rate; nginx CPU %.3f s a client over %.1f s "
              "(%.1f %% of a core a client); %.1f MB fetched in all\n",
              f.clients, f.fetch_only ? " (fetching, not drawing)" : "", worst, cpu / f.clients, wall, 100 * cpu / f.clients / wall, static_cast<double>(bytes) / 1e6);
  // Whether this machine's cores, not the server or the links, bound the clients.
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  std::printf("CPU meanwhile: the clients %.1f s, the proxies %.1f s, nginx %.1f s: %.0f %% of %u cores\n", clients_cpu,
              proxies_cpu, cpu, 100 * (clients_cpu + proxies_cpu + cpu) / (wall * cores), cores);
}

}  // namespace
}  // namespace octocosm

int main(int argc, char** argv) {
  CLI::App app{"octocosm-bench-remote: a store rendered from its directory and from nginx through a throttled link"};
  octocosm::Flags f;
  app.add_option("store", f.store, "store directory (nginx serves its parent directory)")->required();
  app.add_option("--frames", f.frames, "frames of each camera path")->default_val(40)->check(CLI::Range(2, 100000));
  app.add_option("--rtt-ms", f.rtt_ms, "round trip of the link, ms")->default_val(20);
  app.add_option("--rate", f.rate, "bandwidth of each client's link, bytes/s (e.g. 100M)")->default_val("100M");
  app.add_option("--shared-rate", f.shared_rate, "bandwidth the clients share, bytes/s")->default_val("800M");
  app.add_option("--clients", f.clients, "clients at once (0: one client only)")->default_val(8);
  app.add_option("--width", f.width, "image width")->default_val(640);
  app.add_option("--height", f.height, "image height")->default_val(360);
  app.add_option("--error", f.error, "screen-space error threshold, pixels")->default_val(2);
  app.add_option("--cluster-error", f.cluster_error,
                 "draw the cut cluster by cluster at this error (mean particle masses, as octocosm render's "
                 "--cluster-error) instead of refining by --error; not with --fetch-only")
      ->default_val(0)
      ->check(CLI::NonNegativeNumber);
  app.add_option("--backend", f.backend, "osmesa or egl (a GPU)")->default_val("osmesa");
  app.add_option("--follow", f.follow, "IDs to follow through the epochs (0: none; stores with IDs)")->default_val(100);
  app.add_flag("!--no-query", f.query, "skip the box query");
  app.add_flag("--each-alone", f.each_alone,
               "also render the remote path reading every block alone, not blocks near one another together");
  app.add_flag("--fetch-only", f.fetch_only,
               "many clients: fetch each frame's blocks as the renderer would, without drawing (the server's and "
               "link's rate on a machine with fewer cores than clients)");
  app.add_option("--client", f.client_url, "(used by the bench itself) render this store URL's path and print figures");
  app.add_option("--variant", f.variant, "(with --client) which camera path")->default_val(0);
  CLI11_PARSE(app, argc, argv);
  if (f.fetch_only && f.cluster_error > 0) {
    std::fprintf(stderr, "octocosm-bench-remote: --fetch-only selects node by node; --cluster-error needs the renderer\n");
    return 2;
  }
  try {
    if (!f.client_url.empty()) {
      const octocosm::PathRun run = f.fetch_only ? octocosm::FetchPath(f.client_url, f, f.variant)
                                                 : octocosm::RenderPath(f.client_url, f, f.variant);
      std::printf("client %.4f %.4f %.4f %.4f\n", run.open_and_first_s, run.first_pass_fps, run.warm_fps,
                  run.new_view_s);
      return 0;
    }
    octocosm::Coordinate(f);
  } catch (const octocosm::Error& e) {
    std::fprintf(stderr, "octocosm-bench-remote: %s\n", e.what());
    return 1;
  }
  return 0;
}
