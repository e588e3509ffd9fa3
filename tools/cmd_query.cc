// octocosm query and octocosm follow: points of a region at a level of detail,
// and particles followed through the epochs by ID.
#include "tools/cmd_query.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <numeric>
#include <optional>
#include <sstream>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "query/particle_lookup.h"
#include "query/query.h"
#include "tools/camera_flags.h"
#include "tools/cli_util.h"
#include "tools/commands.h"
#include "tools/output_file.h"
#include "tools/query_output.h"
#include "tools/store_flags.h"

namespace octocosm {
namespace {

struct QueryFlags {
  std::string store;
  std::uint32_t epoch = 0;
  std::string box, sphere, planes;
  bool frustum = false;
  CameraFlags camera;
  double aspect = 0;
  std::optional<int> level;
  std::optional<double> error;
  double width = 1920, height = 1080;
  std::string columns, format = "csv", output;
  bool quiet = false;
};

std::unique_ptr<Region> RegionFrom(const QueryFlags& f, const Cube& cube, const std::optional<Camera>& camera) {
  const int given = !f.box.empty() + !f.sphere.empty() + f.frustum + !f.planes.empty();
  if (given > 1) throw Error::InvalidArgument("give at most one of --box, --sphere, --frustum, --planes");
  if (!f.box.empty()) {
    const std::vector<double> v = ParseNumberList(f.box, "--box");
    if (v.size() != 6) throw Error::InvalidArgument("--box '" + f.box + "': expected 6 numbers x0,y0,z0,x1,y1,z1");
    return MakeBoxRegion({v[0], v[1], v[2]}, {v[3], v[4], v[5]}, cube);
  }
  if (!f.sphere.empty()) {
    const std::vector<double> v = ParseNumberList(f.sphere, "--sphere");
    if (v.size() != 4) throw Error::InvalidArgument("--sphere '" + f.sphere + "': expected 4 numbers x,y,z,r");
    return MakeSphereRegion({v[0], v[1], v[2]}, v[3], cube);
  }
  if (f.frustum) {
    if (!camera) throw Error::InvalidArgument("--frustum needs a camera: --camera x,y,z [--look-at ...] or --view-matrix");
    return MakeFrustumRegion(Frustum::FromCamera(*camera));
  }
  if (!f.planes.empty()) {
    const std::vector<double> v = ParseNumberList(f.planes, "--planes");
    if (v.size() != 24) throw Error::InvalidArgument("--planes: expected 24 numbers, 6 planes a,b,c,d (inside: ax+by+cz+d >= 0)");
    std::array<Plane, 6> planes;
    for (int i = 0; i < 6; ++i) planes[i] = Plane{{v[4 * i], v[4 * i + 1], v[4 * i + 2]}, v[4 * i + 3]};
    return MakeFrustumRegion(Frustum::FromPlanes(planes));
  }
  return MakeEverythingRegion();
}

void RunQueryCommand(const QueryFlags& f) {
  const Dataset dataset = Dataset::Open(f.store);
  if (f.epoch >= dataset.epoch_count()) {
    throw Error::InvalidArgument("--epoch " + std::to_string(f.epoch) + ": the store has " +
                                 std::to_string(dataset.epoch_count()) + " epoch(s)");
  }
  const Cube& cube = dataset.cube(f.epoch);
  if (f.level.has_value() == f.error.has_value()) throw Error::InvalidArgument("give exactly one of --level and --error");
  if (!(f.width > 0) || !(f.height > 0)) throw Error::InvalidArgument("--width and --height must be > 0");
  std::optional<Camera> camera;
  if (f.camera.given()) camera = CameraFromFlags(f.camera, cube, f.aspect > 0 ? f.aspect : f.width / f.height);
  QueryOptions options;
  options.epoch = f.epoch;
  options.columns = ParseColumnList(f.columns);
  if (f.level) {
    if (*f.level < 0 || *f.level > kMaxLevel) throw Error::InvalidArgument("--level must be in [0, 21]");
    options.level = *f.level;
  } else {
    if (!camera) throw Error::InvalidArgument("--error needs a camera: --camera x,y,z [--look-at ...] or --view-matrix");
    if (!(*f.error > 0)) throw Error::InvalidArgument("--error must be > 0 pixels");
    options.screen_error = ScreenErrorView{*camera, f.height, *f.error};
  }
  const std::unique_ptr<Region> region = RegionFrom(f, cube, camera);
  const PointFormat format = ParsePointFormat(f.format);

  // A query stopped by an error (a corrupt block, a full disk) leaves no
  // truncated file, nor touches one already there.
  std::optional<OutputFile> output;
  std::ofstream file;
  if (!f.output.empty()) {
    output.emplace(f.output);
    file.open(output->write_path(), std::ios::binary | std::ios::trunc);
    if (!file) throw IoErrorFromErrno(f.output, "open for writing", errno);
  }
  std::ostream& out = f.output.empty() ? std::cout : file;
  const std::unique_ptr<PointWriter> writer = MakePointWriter(format, options.columns, out);
  const QueryStats stats = RunQuery(dataset, *region, options, [&](const QueryBatch& batch) { writer->Write(batch); });
  writer->Finish();
  if (output) {
    file.close();
    if (!file) throw Error::Io(f.output, "write failed");
    output->Commit();
  }
  if (!f.quiet) {
    std::fprintf(stderr,
                 "query: %llu points returned of %llu decoded; %llu nodes selected (%llu index entries visited, %llu "
                 "child scans, %llu index pages read); %llu blocks, %llu reads, %s read\n",
                 static_cast<unsigned long long>(stats.points_returned), static_cast<unsigned long long>(stats.points_scanned),
                 static_cast<unsigned long long>(stats.nodes_selected),
                 static_cast<unsigned long long>(stats.selection.nodes_visited),
                 static_cast<unsigned long long>(stats.selection.index_scans),
                 static_cast<unsigned long long>(stats.selection.index_pages_read),
                 static_cast<unsigned long long>(stats.reads.blocks), static_cast<unsigned long long>(stats.reads.reads),
                 HumanBytes(static_cast<double>(stats.reads.bytes)).c_str());
  }
}

}  // namespace

std::vector<std::uint64_t> ReadIdFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) {
    if (errno == ENOENT) throw Error::NotFound("ID file " + path + " does not exist");
    throw IoErrorFromErrno(path, "open", errno);
  }
  std::vector<std::uint64_t> ids;
  std::string line;
  for (std::size_t number = 1; std::getline(in, line); ++number) {
    const std::size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos) continue;
    const std::size_t last = line.find_last_not_of(" \t\r");
    const std::string text = line.substr(first, last - first + 1);
    std::size_t end = 0;
    unsigned long long value = 0;
    try {
      if (text[0] == '-' || text[0] == '+') throw std::invalid_argument("sign");
      value = std::stoull(text, &end, 10);
    } catch (const std::exception&) {
      end = 0;
    }
    if (end == 0 || end != text.size()) {
      throw Error::BadInput(path, "line " + std::to_string(number) + ": '" + text +
                                      "' is not a particle ID (one non-negative integer per line)");
    }
    ids.push_back(value);
  }
  if (in.bad()) throw Error::Io(path, "read failed");
  return ids;
}

FollowReport WriteTrajectories(const Dataset& dataset, std::span<const std::uint64_t> ids, std::ostream& csv,
                               std::ostream& notes) {
  ParticleLocator locator(dataset);
  // Epoch by epoch (each leaf read once per epoch), then written ID by ID.
  std::vector<std::uint32_t> epochs(dataset.epoch_count());
  std::iota(epochs.begin(), epochs.end(), 0u);
  const std::vector<std::vector<std::optional<ParticleState>>> by_epoch = locator.FindInEpochs(epochs, ids, true);
  bool velocity = false;
  for (const auto& states : by_epoch) {
    for (const auto& state : states) velocity |= state && state->has_velocity;
  }
  FollowReport report;
  csv << (velocity ? "id,epoch,time,x,y,z,vx,vy,vz\n" : "id,epoch,time,x,y,z\n");
  char buffer[256];
  for (std::size_t i = 0; i < ids.size(); ++i) {
    for (std::uint32_t e = 0; e < dataset.epoch_count(); ++e) {
      const std::optional<ParticleState>& state = by_epoch[e][i];
      if (!state) {
        if (report.missing < 100) notes << "follow: particle " << ids[i] << " is not in epoch " << e << "; skipped\n";
        ++report.missing;
        continue;
      }
      std::snprintf(buffer, sizeof buffer, "%llu,%u,%.17g,%.17g,%.17g,%.17g", static_cast<unsigned long long>(ids[i]), e,
                    dataset.store().epochs()[e].time, state->position[0], state->position[1], state->position[2]);
      csv << buffer;
      if (velocity) {
        std::snprintf(buffer, sizeof buffer, ",%.9g,%.9g,%.9g", static_cast<double>(state->velocity[0]),
                      static_cast<double>(state->velocity[1]), static_cast<double>(state->velocity[2]));
        csv << buffer;
      }
      csv << '\n';
      ++report.rows;
    }
  }
  if (report.missing > 100) notes << "follow: " << report.missing << " (id, epoch) pairs not found in all\n";
  csv.flush();
  if (!csv) throw Error::Io("follow output", "write failed (disk full or closed pipe?)");
  return report;
}

void AddQueryCommand(CLI::App& app) {
  auto f = std::make_shared<QueryFlags>();
  CLI::App* cmd = app.add_subcommand(
      "query",
      "Points of one epoch in a region (a box, a sphere, a camera frustum or six planes; default: everything)\n"
      "at a level of detail (--level L, or --error PIXELS for a camera). Positions always; other columns on\n"
      "request. Statistics (blocks and bytes read) go to stderr. Formats: docs/QUERIES.md.");
  AddStoreArgument(*cmd, f->store);
  cmd->add_option("--epoch", f->epoch, "epoch to query")->default_val(0);
  cmd->add_option("--box", f->box, "box x0,y0,z0,x1,y1,z1 (periodic in a periodic store)");
  cmd->add_option("--sphere", f->sphere, "sphere x,y,z,r (periodic in a periodic store)");
  cmd->add_flag("--frustum", f->frustum, "the camera's view frustum (camera flags below)");
  cmd->add_option("--planes", f->planes, "frustum as 6 planes a,b,c,d (24 numbers; inside when ax+by+cz+d >= 0)");
  AddCameraFlags(*cmd, f->camera);
  cmd->add_option("--aspect", f->aspect, "aspect ratio (default: width / height)");
  cmd->add_option("--level", f->level, "level of detail: the nodes at this level plus shallower leaves");
  cmd->add_option("--error", f->error, "level of detail: screen-space error threshold in pixels (needs a camera)");
  cmd->add_option("--width", f->width, "viewport width in pixels")->default_val(1920);
  cmd->add_option("--height", f->height, "viewport height in pixels")->default_val(1080);
  cmd->add_option("--columns", f->columns, "extra columns: weight,smoothing,velocity,id,type,displacement,next_velocity,\n"
                  "prev_displacement,prev_velocity,velocity_dispersion,shape or all");
  cmd->add_option("--format", f->format, "csv, bin (docs/QUERIES.md), ply (binary little endian) or ply-ascii")->default_val("csv");
  cmd->add_option("-o,--output", f->output, "output file (default: stdout)");
  cmd->add_flag("-q,--quiet", f->quiet, "no statistics on stderr");
  cmd->callback([f] { RunQueryCommand(*f); });
}

void AddFollowCommand(CLI::App& app) {
  struct Flags {
    std::string store, ids, output;
  };
  auto f = std::make_shared<Flags>();
  CLI::App* cmd = app.add_subcommand(
      "follow",
      "Follow particles through every epoch by ID: CSV rows id,epoch,time,x,y,z (+vx,vy,vz when stored).\n"
      "IDs missing from an epoch are noted on stderr and skipped.");
  AddStoreArgument(*cmd, f->store);
  cmd->add_option("--ids", f->ids, "file of particle IDs, one per line ('#' comments and blank lines allowed)")->required();
  cmd->add_option("-o,--output", f->output, "output CSV (default: stdout)");
  cmd->callback([f] {
    const std::vector<std::uint64_t> ids = ReadIdFile(f->ids);
    const Dataset dataset = Dataset::Open(f->store);
    std::optional<OutputFile> output;  // whole or not at all, as query's
    std::ofstream file;
    if (!f->output.empty()) {
      output.emplace(f->output);
      file.open(output->write_path(), std::ios::trunc);
      if (!file) throw IoErrorFromErrno(f->output, "open for writing", errno);
    }
    const FollowReport report = WriteTrajectories(dataset, ids, f->output.empty() ? std::cout : file, std::cerr);
    if (output) {
      file.close();
      if (!file) throw Error::Io(f->output, "write failed");
      output->Commit();
    }
    std::fprintf(stderr, "follow: %zu IDs, %llu rows, %llu (id, epoch) pairs not found\n", ids.size(),
                 static_cast<unsigned long long>(report.rows), static_cast<unsigned long long>(report.missing));
  });
}

}  // namespace octocosm
