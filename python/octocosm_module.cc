// The Python module `octocosm`: stores built from snapshots, and a store's
// points, particle trajectories and pictures as numpy arrays
// (docs/PYTHON.md). A thin layer over query/, render/ and ingest/: every
// number comes from the same code as `octocosm ingest`, `query`, `follow`
// and `render`.
#include <dlfcn.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <memory>
#include <numeric>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "base/cancellation.h"
#include "base/error.h"
#include "index/block_codec.h"
#include "index/cluster_shape.h"
#include "index/dataset.h"
#include "ingest/ingest.h"
#include "ingest/snapshot/isolated_process.h"
#include "query/camera_defaults.h"
#include "query/particle_lookup.h"
#include "query/query.h"
#include "render/color_maps.h"
#include "render/offscreen_renderer.h"
#include "render/tone_map.h"
#include "storage/http_file.h"
#include "storage/range_cache.h"

namespace py = pybind11;

namespace octocosm {
namespace {

// A numpy array that owns `values` (moved, not copied), `shape` C-ordered.
template <typename T>
py::array_t<T> OwningArray(std::vector<T>&& values, std::vector<py::ssize_t> shape) {
  auto* owned = new std::vector<T>(std::move(values));
  py::capsule release(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(std::move(shape), owned->data(), release);
}

// The columns of the names given ("all" for every one); position always.
// The cluster links (child_cluster, refine_bound) are a block's, not a
// point's: only Store.blocks returns them, and only when named.
ColumnSet ColumnsNamed(const std::vector<std::string>& names, bool whole_blocks) {
  ColumnSet columns = ColumnBit(ColumnId::kPosition);
  for (const std::string& name : names) {
    if (name == "all") {
      columns |= kAllColumns;
      continue;
    }
    bool known = false;
    for (const ColumnId id : kColumnIds) {
      if (name == ColumnName(id)) {
        columns |= ColumnBit(id);
        known = true;
      }
    }
    if (!known) {
      throw Error::InvalidArgument("unknown column '" + name + "' (known: " +
                                   ColumnNames(kAllColumns | (whole_blocks ? kClusterLinkColumns : 0)) + ", all)");
    }
    if (!whole_blocks && (columns & kClusterLinkColumns)) {
      throw Error::InvalidArgument("column '" + name + "' links a block's clusters to its children's points: "
                                   "Store.blocks returns it, Store.query does not");
    }
  }
  return columns;
}

// Collects the batches of a query column by column, a wanted column that a
// block lacks as zeros (as `octocosm query` writes it), and hands them over
// as numpy arrays: one copy, from the blocks into the result.
class ColumnCollector {
 public:
  explicit ColumnCollector(ColumnSet columns) : columns_(columns) {}

  // Room for `points` in every wanted column, so that adding never moves
  // what was added (address space only: untouched pages cost no memory).
  void Reserve(std::size_t points) {
    position_.reserve(3 * points);
    if (Wants(ColumnId::kWeight)) weight_.reserve(points);
    if (Wants(ColumnId::kSmoothing)) smoothing_.reserve(points);
    if (Wants(ColumnId::kId)) id_.reserve(points);
    if (Wants(ColumnId::kType)) type_.reserve(points);
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      if (Wants(kVectorColumnIds[v])) vectors_[v].reserve(3 * points);
    }
    if (Wants(ColumnId::kVelocityDispersion)) dispersion_.reserve(points);
    if (Wants(ColumnId::kShape)) shape_.reserve(6 * points);
    if (Wants(ColumnId::kRefineBound)) refine_bound_.reserve(3 * points);
  }

  void Add(const NodePoints& points, std::size_t count) {
    Append(position_, points.position, 3 * count);
    if (Wants(ColumnId::kWeight)) Append(weight_, points.weight, count);
    if (Wants(ColumnId::kSmoothing)) Append(smoothing_, points.smoothing, count);
    if (Wants(ColumnId::kId)) Append(id_, points.id, count);
    if (Wants(ColumnId::kType)) Append(type_, points.type, count);
    const auto vectors = VectorColumns(points);
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      if (Wants(kVectorColumnIds[v])) Append(vectors_[v], *vectors[v], 3 * count);
    }
    if (Wants(ColumnId::kVelocityDispersion)) Append(dispersion_, points.velocity_dispersion, count);
    if (Wants(ColumnId::kShape)) {
      // Decoded as `octocosm query` writes them; a leaf's particles, which
      // carry none, are round.
      for (std::size_t i = 0; i < count; ++i) {
        const SymmetricMatrix shape = 6 * i < points.shape.size() ? DecodeShape(ShapeCodeAt(points.shape, i)) : kRoundShape;
        for (const double entry : shape) shape_.push_back(static_cast<float>(entry));
      }
    }
    // A block's own, whole (Store.blocks): a leaf's are empty.
    if (Wants(ColumnId::kChildCluster)) Append(child_cluster_, points.child_cluster, points.child_cluster.size());
    if (Wants(ColumnId::kRefineBound)) Append(refine_bound_, points.refine_bound, 3 * count);
    count_ += count;
  }

  py::dict Take() {
    const auto n = static_cast<py::ssize_t>(count_);
    py::dict result;
    result["position"] = OwningArray(std::move(position_), {n, 3});
    if (Wants(ColumnId::kWeight)) result["weight"] = OwningArray(std::move(weight_), {n});
    if (Wants(ColumnId::kSmoothing)) result["smoothing"] = OwningArray(std::move(smoothing_), {n});
    if (Wants(ColumnId::kId)) result["id"] = OwningArray(std::move(id_), {n});
    if (Wants(ColumnId::kType)) result["type"] = OwningArray(std::move(type_), {n});
    for (std::size_t v = 0; v < kVectorColumnCount; ++v) {
      if (Wants(kVectorColumnIds[v])) result[ColumnName(kVectorColumnIds[v])] = OwningArray(std::move(vectors_[v]), {n, 3});
    }
    if (Wants(ColumnId::kVelocityDispersion)) result["velocity_dispersion"] = OwningArray(std::move(dispersion_), {n});
    if (Wants(ColumnId::kShape)) result["shape"] = OwningArray(std::move(shape_), {n, 6});
    if (Wants(ColumnId::kChildCluster)) {
      const auto entries = static_cast<py::ssize_t>(child_cluster_.size());
      result["child_cluster"] = OwningArray(std::move(child_cluster_), {entries});
    }
    if (Wants(ColumnId::kRefineBound)) result["refine_bound"] = OwningArray(std::move(refine_bound_), {n, 3});
    count_ = 0;
    return result;
  }

 private:
  bool Wants(ColumnId id) const { return (columns_ & ColumnBit(id)) != 0; }
  template <typename T>
  static void Append(std::vector<T>& out, const std::vector<T>& values, std::size_t size) {
    if (values.size() == size) {
      out.insert(out.end(), values.begin(), values.end());
    } else {
      out.resize(out.size() + size, T{});
    }
  }

  ColumnSet columns_;
  std::size_t count_ = 0;
  std::vector<double> position_, weight_, smoothing_;
  std::vector<std::uint64_t> id_;
  std::vector<std::uint8_t> type_;
  std::array<std::vector<float>, kVectorColumnCount> vectors_;
  std::vector<float> shape_;  // xx, yy, zz, xy, xz, yz of each point's blob shape (trace 3)
  std::vector<float> dispersion_;
  std::vector<std::uint32_t> child_cluster_;
  std::vector<float> refine_bound_;
};

std::array<double, 3> Triple(const py::handle& value, const char* what) {
  const auto v = value.cast<std::vector<double>>();
  if (v.size() != 3) throw Error::InvalidArgument(std::string(what) + ": expected 3 numbers");
  return {v[0], v[1], v[2]};
}

// A camera from a dict (None: all defaults) of position, look_at, up (3
// numbers each), fov_y_degrees, near and far, with the command-line
// program's defaults for `cube` (query/camera_defaults.h): the whole cube in
// view from +z, looking at its centre; the aspect from the viewport.
Camera CameraFrom(const py::object& spec, const Cube& cube, double aspect) {
  Camera camera;
  std::optional<std::array<double, 3>> position, look_at;
  std::optional<double> near, far;
  if (!spec.is_none()) {
    for (const auto& [key, value] : spec.cast<py::dict>()) {
      const std::string name = key.cast<std::string>();
      if (name == "position") {
        position = Triple(value, "camera position");
      } else if (name == "look_at") {
        look_at = Triple(value, "camera look_at");
      } else if (name == "up") {
        camera.up = Triple(value, "camera up");
      } else if (name == "fov_y_degrees") {
        camera.fov_y_degrees = value.cast<double>();
      } else if (name == "near") {
        near = value.cast<double>();
      } else if (name == "far") {
        far = value.cast<double>();
      } else {
        throw Error::InvalidArgument("camera: unknown key '" + name +
                                     "' (known: position, look_at, up, fov_y_degrees, near, far)");
      }
    }
  }
  camera.position = position.value_or(OverviewPosition(cube, camera.fov_y_degrees));
  camera.look_at = look_at.value_or(CubeCentre(cube));
  camera.near = near.value_or(DefaultNear(cube));
  camera.far = far.value_or(DefaultFar(camera.position, cube));
  camera.aspect = aspect;
  camera.Validate();
  return camera;
}

// What a query asks, from the keyword arguments of Store.query and
// Store.blocks.
struct QuerySpec {
  QueryOptions options;
  std::unique_ptr<Region> region;
};

QuerySpec MakeQuery(const Dataset& dataset, std::uint32_t epoch, const py::object& box, const py::object& sphere,
                    bool frustum, std::optional<int> level, std::optional<double> error, const py::object& camera,
                    double width, double height, const std::vector<std::string>& columns, bool whole_blocks) {
  if (epoch >= dataset.epoch_count()) {
    throw Error::InvalidArgument("epoch " + std::to_string(epoch) + ": the store has " +
                                 std::to_string(dataset.epoch_count()) + " epoch(s)");
  }
  if (level.has_value() == error.has_value()) throw Error::InvalidArgument("give exactly one of level and error");
  if (!(width > 0) || !(height > 0)) throw Error::InvalidArgument("width and height must be > 0");
  const Cube& cube = dataset.cube(epoch);
  std::optional<Camera> view;
  if (!camera.is_none()) view = CameraFrom(camera, cube, width / height);
  QuerySpec spec;
  spec.options.epoch = epoch;
  spec.options.columns = ColumnsNamed(columns, whole_blocks);
  if (level) {
    if (*level < 0 || *level > kMaxLevel) throw Error::InvalidArgument("level must be in [0, 21]");
    spec.options.level = *level;
  } else {
    if (!view) throw Error::InvalidArgument("error needs a camera");
    if (!(*error > 0)) throw Error::InvalidArgument("error must be > 0 pixels");
    spec.options.screen_error = ScreenErrorView{*view, height, *error};
  }
  if (!box.is_none() + !sphere.is_none() + frustum > 1) {
    throw Error::InvalidArgument("give at most one of box, sphere and frustum");
  }
  if (!box.is_none()) {
    const auto v = box.cast<std::vector<double>>();
    if (v.size() != 6) throw Error::InvalidArgument("box: expected 6 numbers x0, y0, z0, x1, y1, z1");
    spec.region = MakeBoxRegion({v[0], v[1], v[2]}, {v[3], v[4], v[5]}, cube);
  } else if (!sphere.is_none()) {
    const auto v = sphere.cast<std::vector<double>>();
    if (v.size() != 4) throw Error::InvalidArgument("sphere: expected 4 numbers x, y, z, r");
    spec.region = MakeSphereRegion({v[0], v[1], v[2]}, v[3], cube);
  } else if (frustum) {
    if (!view) throw Error::InvalidArgument("frustum needs a camera");
    spec.region = MakeFrustumRegion(Frustum::FromCamera(*view));
  } else {
    spec.region = MakeEverythingRegion();
  }
  return spec;
}

py::dict StatsDict(const QueryStats& stats) {
  py::dict d;
  d["nodes_selected"] = stats.nodes_selected;
  d["points_selected"] = stats.points_selected;
  d["blocks_read"] = stats.reads.blocks;
  d["bytes_read"] = stats.reads.bytes;
  d["points_scanned"] = stats.points_scanned;
  d["points_returned"] = stats.points_returned;
  return d;
}

// Store.blocks(): the blocks of a query one at a time, each a dict of its
// points' columns (moved into numpy, no copy) and its node key.
class BlockIterator {
 public:
  BlockIterator(std::shared_ptr<const Dataset> dataset, QuerySpec spec)
      : dataset_(std::move(dataset)), spec_(std::move(spec)), cursor_(*dataset_, *spec_.region, spec_.options) {}

  py::dict Next() {
    QueryBatch batch;
    bool more = false;
    {
      py::gil_scoped_release release;
      more = cursor_.Next(batch);
    }
    if (!more) throw py::stop_iteration();
    ColumnCollector collector(spec_.options.columns);
    collector.Add(batch.points, batch.count);
    py::dict block = collector.Take();
    block["node"] = batch.node.value();
    block["level"] = batch.node.level();
    return block;
  }

  py::dict Stats() const { return StatsDict(cursor_.stats()); }

 private:
  std::shared_ptr<const Dataset> dataset_;  // kept alive while the iterator is
  QuerySpec spec_;
  QueryCursor cursor_;
};

class Store {
 public:
  explicit Store(const std::string& path) : path_(path) {
    py::gil_scoped_release release;
    dataset_ = std::make_shared<const Dataset>(Dataset::Open(path));
  }

  std::uint32_t epochs() const { return dataset_->epoch_count(); }

  py::dict Info() const {
    const Dataset& d = *dataset_;
    py::dict info;
    info["path"] = path_;
    info["page_size"] = d.store().page_size();
    info["capacity"] = d.capacity();
    info["columns"] = ColumnNames(d.columns());
    py::list epochs;
    for (std::uint32_t e = 0; e < d.epoch_count(); ++e) {
      const EpochInfo& stored = d.store().epochs()[e];
      const EpochSummary& summary = d.summary(e);
      const Cube& cube = d.cube(e);
      py::dict epoch;
      epoch["epoch"] = e;
      epoch["time"] = stored.time;
      epoch["redshift"] = stored.redshift;
      epoch["points"] = summary.points;
      epoch["mass"] = summary.mass ? py::cast(*summary.mass) : py::none();
      epoch["nodes"] = summary.nodes ? py::cast(*summary.nodes) : py::none();
      epoch["depth"] = summary.depth ? py::cast(*summary.depth) : py::none();
      epoch["cube_origin"] = py::make_tuple(cube.origin[0], cube.origin[1], cube.origin[2]);
      epoch["cube_size"] = cube.size;
      epoch["periodic"] = cube.periodic;
      epoch["columns"] = ColumnNames(d.columns(e));
      epochs.append(epoch);
    }
    info["epochs"] = epochs;
    return info;
  }

  py::dict Query(std::uint32_t epoch, const py::object& box, const py::object& sphere, bool frustum,
                 std::optional<int> level, std::optional<double> error, const py::object& camera, double width,
                 double height, const std::vector<std::string>& columns, bool with_stats) const {
    QuerySpec spec = MakeQuery(*dataset_, epoch, box, sphere, frustum, level, error, camera, width, height, columns, false);
    ColumnCollector collector(spec.options.columns);
    QueryStats stats;
    {
      py::gil_scoped_release release;
      QueryCursor cursor(*dataset_, *spec.region, spec.options);
      collector.Reserve(cursor.stats().points_selected);
      QueryBatch batch;
      while (cursor.Next(batch)) collector.Add(batch.points, batch.count);
      stats = cursor.stats();
    }
    py::dict result = collector.Take();
    if (with_stats) result["stats"] = StatsDict(stats);
    return result;
  }

  BlockIterator Blocks(std::uint32_t epoch, const py::object& box, const py::object& sphere, bool frustum,
                       std::optional<int> level, std::optional<double> error, const py::object& camera,
                       double width, double height, const std::vector<std::string>& columns) const {
    QuerySpec spec = MakeQuery(*dataset_, epoch, box, sphere, frustum, level, error, camera, width, height, columns, true);
    py::gil_scoped_release release;
    return BlockIterator(dataset_, std::move(spec));
  }

  // Every (id, epoch) pair found, ordered by ID as given, then epoch: what
  // `octocosm follow` writes, as columns.
  py::dict Follow(const std::vector<std::uint64_t>& ids) const {
    const Dataset& d = *dataset_;
    std::vector<std::vector<std::optional<ParticleState>>> by_epoch;
    bool velocity = false;
    {
      py::gil_scoped_release release;
      ParticleLocator locator(d);
      std::vector<std::uint32_t> epochs(d.epoch_count());
      std::iota(epochs.begin(), epochs.end(), 0u);
      by_epoch = locator.FindInEpochs(epochs, ids, true);
      for (const auto& states : by_epoch) {
        for (const auto& state : states) velocity |= state && state->has_velocity;
      }
    }
    std::vector<std::uint64_t> id;
    std::vector<std::uint32_t> epoch;
    std::vector<double> time, position;
    std::vector<float> velocities;
    for (std::size_t i = 0; i < ids.size(); ++i) {
      for (std::uint32_t e = 0; e < d.epoch_count(); ++e) {
        const std::optional<ParticleState>& state = by_epoch[e][i];
        if (!state) continue;
        id.push_back(ids[i]);
        epoch.push_back(e);
        time.push_back(d.store().epochs()[e].time);
        position.insert(position.end(), state->position.begin(), state->position.end());
        if (velocity) velocities.insert(velocities.end(), state->velocity.begin(), state->velocity.end());
      }
    }
    const auto n = static_cast<py::ssize_t>(id.size());
    py::dict result;
    result["id"] = OwningArray(std::move(id), {n});
    result["epoch"] = OwningArray(std::move(epoch), {n});
    result["time"] = OwningArray(std::move(time), {n});
    result["position"] = OwningArray(std::move(position), {n, 3});
    if (velocity) result["velocity"] = OwningArray(std::move(velocities), {n, 3});
    return result;
  }

  // A picture of the store at fractional epoch `time` (or at a redshift or
  // scale factor), as `octocosm render` draws it: the mass per pixel, the
  // selected particles' share of it and the tone-mapped colours, row 0 at
  // the top (as in the PNG).
  py::dict Render(const py::object& camera, std::optional<double> epoch_time, std::optional<double> redshift,
                  std::optional<double> scale_factor, int width, int height, double error, double cluster_error,
                  std::uint64_t budget, bool full, double exposure, const std::string& curve, const std::string& colormap,
                  const std::string& color, const std::vector<std::uint64_t>& select, const std::string& backend) {
    const Dataset& d = *dataset_;
    if (epoch_time.has_value() + redshift.has_value() + scale_factor.has_value() > 1) {
      throw Error::InvalidArgument("give at most one of time, redshift and scale_factor");
    }
    double time = epoch_time.value_or(0);
    if (redshift) time = d.FractionalEpochAt({PhysicalTime::Scale::kRedshift, *redshift});
    if (scale_factor) time = d.FractionalEpochAt({PhysicalTime::Scale::kScaleFactor, *scale_factor});
    if (!(time >= 0 && time <= d.epoch_count() - 1.0)) {
      throw Error::InvalidArgument("time must be in [0, " + std::to_string(d.epoch_count() - 1) + "] (epochs)");
    }
    if (!full && !(error > 0)) throw Error::InvalidArgument("error must be > 0 pixels");
    if (!(cluster_error >= 0) || !std::isfinite(cluster_error)) throw Error::InvalidArgument("cluster_error must be finite and >= 0");
    if (cluster_error > 0 && (d.cluster_columns() & kClusterLinkColumns) != kClusterLinkColumns) {
      throw Error::InvalidArgument("cluster_error: the store " + d.store().directory() +
                                   " does not link its clusters to their children's points; use error instead");
    }
    if (width < 1 || height < 1) throw Error::InvalidArgument("width and height must be >= 1");
    const Cube& cube = d.cube(static_cast<std::uint32_t>(std::lround(time)));
    const RenderView view(CameraFrom(camera, cube, static_cast<double>(width) / height), width, height);
    LodOptions lod;
    lod.pixel_threshold = full ? 1e-9 : error;
    lod.point_budget = full ? 0 : budget;
    const ColorMode mode = ParseColorMode(color);
    ToneMapSettings tone;
    tone.curve = ParseToneCurve(curve);
    tone.exposure = exposure;
    tone.density_map = ParseColorMap(colormap);
    tone.color = mode;
    tone.attribute_map = DefaultAttributeColorMap(mode);
    tone.Validate();
    const HeadlessBackend headless = ParseHeadlessBackend(backend);
    Picture picture;
    {
      py::gil_scoped_release release;
      OffscreenRenderer& renderer = Renderer(headless);
      renderer.scene().SetLod(lod);
      // Every particle: the cut with the threshold ~0 (as --full does).
      renderer.scene().SetClusterError(full && cluster_error > 0 ? 1e-300 : cluster_error);
      renderer.scene().SetColorMode(mode);
      renderer.scene().SetSelection(select);
      picture = renderer.Render(view, time, tone, true);
    }
    const HdrImage& hdr = *picture.hdr;
    const auto w = static_cast<std::size_t>(width), h = static_cast<std::size_t>(height);
    std::vector<double> mass(w * h), selected(w * h);
    std::vector<std::uint8_t> rgb(3 * w * h);
    for (std::size_t j = 0; j < h; ++j) {  // the images' rows run bottom to top
      const std::size_t from = (h - 1 - j) * w;
      for (std::size_t i = 0; i < w; ++i) {
        mass[j * w + i] = hdr.rgba[4 * (from + i)];
        selected[j * w + i] = hdr.rgba[4 * (from + i) + 3];
      }
      std::copy_n(picture.rgb.rgb.begin() + static_cast<std::ptrdiff_t>(3 * from), 3 * w,
                  rgb.begin() + static_cast<std::ptrdiff_t>(3 * j * w));
    }
    py::dict result;
    result["mass"] = OwningArray(std::move(mass), {height, width});
    result["selected_mass"] = OwningArray(std::move(selected), {height, width});
    result["rgb"] = OwningArray(std::move(rgb), {height, width, 3});
    result["time"] = time;
    result["exposure"] = picture.tone.exposure;
    result["points_drawn"] = picture.stats.points_drawn;
    result["nodes_selected"] = picture.stats.nodes_selected;
    result["seconds"] = picture.seconds;
    return result;
  }

 private:
  // The renderer of this store for `backend`, made on first use on this
  // thread: an OpenGL context is current on the thread that made it.
  OffscreenRenderer& Renderer(HeadlessBackend backend) {
    if (!renderer_ || renderer_backend_ != backend || renderer_thread_ != std::this_thread::get_id()) {
      renderer_.reset();
      renderer_ = std::make_unique<OffscreenRenderer>(*dataset_, backend, SceneOptions{});
      renderer_backend_ = backend;
      renderer_thread_ = std::this_thread::get_id();
    }
    return *renderer_;
  }

  std::string path_;
  std::shared_ptr<const Dataset> dataset_;
  std::unique_ptr<OffscreenRenderer> renderer_;
  HeadlessBackend renderer_backend_ = HeadlessBackend::kOsMesa;
  std::thread::id renderer_thread_;
};

// octocosm.ingest: snapshots into a new store, as `octocosm ingest` with its
// defaults; progress on stderr unless quiet.
py::dict RunIngest(const std::vector<std::string>& inputs, const std::string& output, std::size_t capacity,
                   int neighbours, std::uint64_t memory, unsigned threads, const std::string& coarse, bool quiet) {
  IngestOptions options;
  options.inputs = inputs;
  options.output = output;
  options.tree.capacity = capacity;
  options.neighbours = neighbours;
  options.memory_budget = memory;
  options.threads = threads;
  options.quiet = quiet;
  if (coarse != "clusters" && coarse != "sample") {
    throw Error::InvalidArgument("coarse: expected clusters or sample, not '" + coarse + "'");
  }
  options.tree.coarse = coarse == "sample" ? CoarsePoints::kSample : CoarsePoints::kClusters;
  // The ingest runs on a thread of its own while this one, the
  // interpreter's, looks for Ctrl-C: Python's handler only sets a flag,
  // which nothing would read before a long ingest ends.
  IngestReport report;
  std::exception_ptr failure;
  std::atomic<bool> done{false};
  ClearCancellation();
  std::thread worker([&] {
    try {
      report = Ingest(options);
    } catch (...) {
      failure = std::current_exception();
    }
    done = true;
  });
  bool interrupted = false;
  while (!done) {
    {
      py::gil_scoped_release release;
      for (int i = 0; i < 10 && !done; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (!interrupted && PyErr_CheckSignals() != 0) {
      interrupted = true;  // KeyboardInterrupt is set; the ingest unwinds, removing what it wrote
      RequestCancellation();
    }
  }
  worker.join();
  ClearCancellation();
  if (interrupted) throw py::error_already_set();
  if (failure) std::rethrow_exception(failure);
  py::dict result;
  result["points"] = report.input_points;
  result["read_points"] = report.read_points;
  result["dropped_points"] = report.dropped_points;
  py::list epochs;
  for (const EpochReport& e : report.epochs) {
    py::dict epoch;
    epoch["points"] = e.points;
    epoch["nodes"] = e.nodes;
    epoch["leaves"] = e.leaves;
    epoch["depth"] = e.depth;
    epoch["mass"] = e.mass;
    py::dict phases;
    for (const EpochReport::Phase& phase : e.phases) phases[phase.name.c_str()] = phase.seconds;
    epoch["seconds"] = phases;
    epochs.append(epoch);
  }
  result["epochs"] = epochs;
  return result;
}

// The octocosm program: OCTOCOSM_PROGRAM; else the one installed beside
// this module (PREFIX/bin for a module in PREFIX/lib/pythonX.Y/dist-packages,
// python/CMakeLists.txt); else the one of the build this module comes from.
std::string ServiceProgram() {
  if (const char* program = std::getenv("OCTOCOSM_PROGRAM")) return program;
  Dl_info module{};
  if (dladdr(reinterpret_cast<void*>(&ServiceProgram), &module) != 0 && module.dli_fname != nullptr) {
    const std::filesystem::path installed =
        (std::filesystem::path(module.dli_fname).parent_path() / "../../../bin/octocosm").lexically_normal();
    if (access(installed.c_str(), X_OK) == 0) return installed.string();
  }
  return OCTOCOSM_PROGRAM_PATH;
}

}  // namespace
}  // namespace octocosm

PYBIND11_MODULE(octocosm, m) {
  using namespace octocosm;
  m.doc() = "octocosm stores from Python: queries and trajectories as numpy arrays (docs/PYTHON.md)";

  // One family of exceptions, each carrying the kind of octocosm::Error.
  static py::exception<Error> error(m, "Error");
  static py::exception<Error> io_error(m, "IoError", error.ptr());
  static py::exception<Error> corruption(m, "CorruptionError", error.ptr());
  static py::exception<Error> not_supported(m, "NotSupportedError", error.ptr());
  static py::exception<Error> invalid_argument(m, "InvalidArgumentError", error.ptr());
  static py::exception<Error> not_found(m, "NotFoundError", error.ptr());
  static py::exception<Error> bad_input(m, "BadInputError", error.ptr());
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const Error& e) {
      py::exception<Error>* type = &error;
      switch (e.kind()) {
        case ErrorKind::kIo: type = &io_error; break;
        case ErrorKind::kCorruption: type = &corruption; break;
        case ErrorKind::kNotSupported: type = &not_supported; break;
        case ErrorKind::kInvalidArgument: type = &invalid_argument; break;
        case ErrorKind::kNotFound: type = &not_found; break;
        case ErrorKind::kBadInput: type = &bad_input; break;
      }
      py::object instance = py::reinterpret_borrow<py::object>(type->ptr())(e.what());
      instance.attr("kind") = std::string(ErrorKindName(e.kind()));
      PyErr_SetObject(type->ptr(), instance.ptr());
    }
  });

  py::class_<BlockIterator>(m, "BlockIterator")
      .def("__iter__", [](BlockIterator& it) -> BlockIterator& { return it; })
      .def("__next__", &BlockIterator::Next)
      .def_property_readonly("stats", &BlockIterator::Stats, "what was selected, and read and returned so far");

  py::class_<Store>(m, "Store")
      .def(py::init<const std::string&>(), py::arg("path"), "Opens the store directory at path.")
      .def_property_readonly("epochs", &Store::epochs, "the number of epochs")
      .def("info", &Store::Info, "the store's epochs (time, redshift, points, cube, columns) as a dict")
      .def("query", &Store::Query, py::arg("epoch") = 0, py::arg("box") = py::none(), py::arg("sphere") = py::none(),
           py::arg("frustum") = false, py::arg("level") = py::none(), py::arg("error") = py::none(),
           py::arg("camera") = py::none(), py::arg("width") = 1920.0, py::arg("height") = 1080.0,
           py::arg("columns") = std::vector<std::string>{}, py::arg("stats") = false,
           "The points of one epoch in a region (box=(x0,y0,z0,x1,y1,z1), sphere=(x,y,z,r), frustum=True\n"
           "with a camera; default everything) at a level of detail (level=L, or error=PIXELS with a camera\n"
           "dict: position, look_at[, up, fov_y_degrees, near, far]), as a dict of numpy arrays: position\n"
           "(n, 3) float64 always, and the columns asked for. stats=True adds what was read.")
      .def("blocks", &Store::Blocks, py::arg("epoch") = 0, py::arg("box") = py::none(),
           py::arg("sphere") = py::none(), py::arg("frustum") = false, py::arg("level") = py::none(),
           py::arg("error") = py::none(), py::arg("camera") = py::none(), py::arg("width") = 1920.0,
           py::arg("height") = 1080.0, py::arg("columns") = std::vector<std::string>{},
           "As query, block by block: an iterator of dicts (the block's columns, its node key and level),\n"
           "for results larger than memory. Besides query's columns, an inner node's cluster links:\n"
           "child_cluster (each of its children's points' cluster in it, children in octant order) and\n"
           "refine_bound (R, a, r of each cluster; docs/FORMAT.md section 4), of blocks the region holds whole.")
      .def("follow", &Store::Follow, py::arg("ids"),
           "Particles followed through every epoch by ID: a dict of numpy arrays id, epoch, time,\n"
           "position (m, 3) and velocity (m, 3) when stored, one row per (id, epoch) found.")
      .def("render", &Store::Render, py::arg("camera") = py::none(), py::arg("time") = py::none(),
           py::arg("redshift") = py::none(), py::arg("scale_factor") = py::none(), py::arg("width") = 640,
           py::arg("height") = 360, py::arg("error") = 1.0, py::arg("cluster_error") = 0.0, py::arg("budget") = 0,
           py::arg("full") = false,
           py::arg("exposure") = 0.0, py::arg("curve") = "log", py::arg("colormap") = "magma",
           py::arg("color") = "density", py::arg("select") = std::vector<std::uint64_t>{},
           py::arg("backend") = "osmesa",
           "A picture as octocosm render draws it, at fractional epoch time (default 0) or at a redshift\n"
           "or scale factor, through the camera dict (default: the whole cube from +z): a dict with mass\n"
           "(height, width) float64, the mass per pixel; selected_mass, the part of it of the particles\n"
           "whose IDs select lists (highlighted, drawn at full detail); rgb (height, width, 3) uint8, row 0\n"
           "at the top; time (the fractional epoch), exposure, points_drawn, nodes_selected, seconds.\n"
           "error: the level of detail in pixels; cluster_error > 0: cluster by cluster instead, where the\n"
           "store links its clusters (as --cluster-error, in mean particle masses); full=True: every particle.");

  m.def(
      "open",
      [](const std::string& path, std::optional<std::string> cache_dir, std::uint64_t cache_size) {
        if (cache_dir) {
          HttpOptions options = DefaultHttpOptions();
          options.cache = RangeCache::Open(*cache_dir, cache_size);
          SetDefaultHttpOptions(options);
        }
        return Store(path);
      },
      py::arg("path"), py::arg("cache_dir") = py::none(), py::arg("cache_size") = std::uint64_t{4} << 30,
      "Opens the store at path: a directory, or the URL of one on an HTTP(S) server (http://host/path).\n"
      "cache_dir keeps the pages fetched from servers between runs, within cache_size bytes; it holds\n"
      "for this and every later store opened over HTTP in this process.");
  m.def("ingest", &RunIngest, py::arg("inputs"), py::arg("output"), py::arg("capacity") = 16000,
        py::arg("neighbours") = kDefaultNeighbours, py::arg("memory") = 0, py::arg("threads") = 0,
        py::arg("coarse") = "clusters", py::arg("quiet") = false,
        "Builds a store at output from snapshots (one per epoch, in time order), as octocosm ingest:\n"
        "capacity points per node, smoothing lengths from neighbours nearest neighbours (0: none),\n"
        "memory budget in bytes (0: the default), threads (0: all cores), coarse 'clusters' or\n"
        "'sample'. Progress goes to stderr unless quiet. Returns what was built, per epoch.");

  // Snapshot readers run some libraries in processes of their own
  // (ingest/snapshot/isolated_process.h), started from the octocosm
  // program, since python3 cannot serve them.
  SetIsolatedProgram(ServiceProgram());
}
