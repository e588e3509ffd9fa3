#include "ingest/smoothing_pass.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <optional>
#include <span>
#include <vector>

#include "base/cancellation.h"
#include "base/error.h"
#include "base/mutex.h"
#include "base/parallel_for.h"
#include "base/progress.h"
#include "base/temp_directory.h"
#include "index/cube.h"
#include "index/morton.h"
#include "ingest/record_file.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;

// Memory per particle held for a search, at its peak while a load is put in
// Morton order: its position and the sorted copy (48 bytes), its key and
// index (16), its query, the query's key and the sorted queries (80 for a
// query). Measured: 10^7 particles searched in memory peaked about 1,000
// MiB above the program's own.
constexpr std::uint64_t kBytesPerLoadedPoint = 112;
// A task's k-d tree is built as blocks side by side, about this many per
// thread (ahead of the slowest), none smaller than kMinBlockPoints: every
// query tests each block's box, and a small block's tree saves little.
constexpr std::size_t kBlocksPerThread = 4;
constexpr std::size_t kMinBlockPoints = std::size_t{1} << 17;
// A Morton key and the index of its point.
using Keyed = std::pair<std::uint64_t, std::uint32_t>;
constexpr std::uint64_t kDefaultBudget = std::uint64_t{1} << 30;
// The count grid that cuts an out-of-core domain into regions: 2^7 cells a
// side, 8 MiB of counts.
constexpr int kCountGridBits = 7;
constexpr int kCountGridSide = 1 << kCountGridBits;
// A search shared by several parts cuts at least this many regions a part,
// so that the parts' shares of the particles come out about even.
constexpr std::uint64_t kRegionsPerPart = 8;
// A sphere is inside a load if it is with this relative room to spare, so
// that rounding in the distances never keeps a radius a missing particle
// could have shortened.
constexpr double kRoom = 1e-9;
constexpr double kInfinity = std::numeric_limits<double>::infinity();

using Vec3 = std::array<double, 3>;

double Distance(const Vec3& a, const Vec3& b) {
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
}

// Frees a vector's memory. (`v = {}` only empties it: it picks the
// initializer-list assignment, which keeps the capacity. That kept every
// region's buffers of the out-of-core search alive, about 130 bytes a
// particle whatever the budget.)
template <typename T>
void Release(std::vector<T>& v) {
  std::vector<T>().swap(v);
}

// [lo, hi) on every axis.
struct Box {
  Vec3 lo{-kInfinity, -kInfinity, -kInfinity};
  Vec3 hi{kInfinity, kInfinity, kInfinity};

  bool Contains(const double* p) const {
    for (int a = 0; a < 3; ++a) {
      if (!(p[a] >= lo[a] && p[a] < hi[a])) return false;
    }
    return true;
  }
};

// The particles of a snapshot live in the domain: the periodic box, or in a
// non-periodic snapshot their bounding cube (once known; until then the
// whole space).
struct Domain {
  bool periodic = false;
  Box box;
  Cube cube;  // the periodic box (to wrap positions), or the bounding cube

  double edge() const { return cube.size; }
};

// Part of a load: the particles inside `box` (in the domain) are loaded at
// their position + shift (a periodic image).
struct Piece {
  Box box;
  Vec3 shift{0, 0, 0};
};

struct Query {
  std::uint64_t ordinal;  // in the source's order
  Vec3 position;          // in the task's frame
};

// One search: the queries, and the particles loaded around them.
struct Task {
  Box region;                    // first round: every particle here without a smoothing length is a query
  bool explicit_queries = false;  // later rounds: the queries are given
  std::vector<Query> queries;
  Box load;                      // what the pieces cover, in the task's frame
  std::vector<Piece> pieces;
  std::uint64_t estimate = 0;    // particles the load is expected to hold
  std::uint64_t count = 0;       // particles in the region (first round)
  std::vector<double> positions;  // the loaded particles, in the task's frame
  // Where NeighbourRadii's blocks start in `positions`, and the block whose
  // key range holds each query (SortSpatially).
  std::vector<std::size_t> block_begins;
  std::vector<std::uint32_t> query_blocks;
};

struct Unresolved {
  std::uint64_t ordinal;
  Vec3 position;  // in the domain
  double radius;  // an upper bound of the true radius (infinity: fewer than k were loaded)
};

// A particle in a region's temporary file.
struct SpilledParticle {
  double position[3];
  std::uint64_t ordinal;  // kQueryBit set when the particle is one of the task's queries
};
constexpr std::uint64_t kQueryBit = std::uint64_t{1} << 63;

// A length a process of a shared pass found, for the process that reads
// the particle's batch.
struct FoundLength {
  std::uint64_t ordinal;
  float length;
  std::uint32_t unused = 0;
};

// A particle a process of a shared pass sends another that wants it.
struct SharedParticle {
  double position[3];     // in the domain
  std::uint64_t ordinal;  // kGivenBit set when the snapshot gives its length
};
constexpr std::uint64_t kGivenBit = std::uint64_t{1} << 63;

// Which processes of a shared pass want a particle: those one of whose
// boxes holds it, found through a coarse grid over the domain listing the
// boxes that touch each cell.
class Router {
 public:
  Router(const std::vector<std::vector<Box>>& wanted, const Domain& domain) : domain_(domain), cells_(kSide * kSide * kSide) {
    for (unsigned q = 0; q < wanted.size(); ++q) {
      for (const Box& box : wanted[q]) {
        std::array<std::size_t, 3> first{}, last{};
        bool empty = false;
        for (int a = 0; a < 3; ++a) {
          const double lo = std::max(box.lo[a], domain.box.lo[a]), hi = std::min(box.hi[a], domain.box.hi[a]);
          empty = empty || !(lo < hi);
          first[static_cast<std::size_t>(a)] = Cell(lo, a);
          last[static_cast<std::size_t>(a)] = Cell(hi, a);
        }
        if (empty) continue;
        const std::uint32_t index = static_cast<std::uint32_t>(boxes_.size());
        boxes_.push_back({box, q});
        for (std::size_t z = first[2]; z <= last[2]; ++z) {
          for (std::size_t y = first[1]; y <= last[1]; ++y) {
            for (std::size_t x = first[0]; x <= last[0]; ++x) cells_[x + kSide * (y + kSide * z)].push_back(index);
          }
        }
      }
    }
  }

  // Calls `to(q)` once for each process q that wants the particle at `p`.
  template <typename To>
  void Route(const double* p, To to) const {
    const auto& candidates = cells_[Cell(p[0], 0) + kSide * (Cell(p[1], 1) + kSide * Cell(p[2], 2))];
    unsigned last = ~0u;
    for (const std::uint32_t index : candidates) {  // in process order
      const auto& [box, q] = boxes_[index];
      if (q != last && box.Contains(p)) {
        to(q);
        last = q;
      }
    }
  }

 private:
  static constexpr std::size_t kSide = 32;
  std::size_t Cell(double coordinate, int a) const {
    const double t = (coordinate - domain_.cube.origin[static_cast<std::size_t>(a)]) / domain_.edge();
    return static_cast<std::size_t>(std::clamp(std::floor(t * kSide), 0.0, static_cast<double>(kSide - 1)));
  }

  const Domain& domain_;
  std::vector<std::pair<Box, unsigned>> boxes_;
  std::vector<std::vector<std::uint32_t>> cells_;
};

// Every box of the pieces of `tasks`' loads.
std::vector<Box> LoadBoxes(const std::vector<Task>& tasks) {
  std::vector<Box> boxes;
  for (const Task& task : tasks) {
    for (const Piece& piece : task.pieces) boxes.push_back(piece.box);
  }
  return boxes;
}

// An order-keeping map of doubles to unsigned integers, so that the ranks'
// largest and smallest coordinates combine exactly through RankGroup::Max.
std::uint64_t Ordered(double value) {
  std::uint64_t bits;
  std::memcpy(&bits, &value, sizeof bits);
  return (bits >> 63) ? ~bits : bits | (std::uint64_t{1} << 63);
}
double FromOrdered(std::uint64_t ordered) {
  const std::uint64_t bits = (ordered >> 63) ? ordered & ~(std::uint64_t{1} << 63) : ~ordered;
  double value;
  std::memcpy(&value, &bits, sizeof value);
  return value;
}

// The pieces of the domain that make up `load`: itself in a non-periodic
// domain, and in a periodic one its images inside the box, each shifted back.
std::vector<Piece> PiecesOf(const Box& load, const Domain& domain) {
  if (!domain.periodic) return {Piece{load, {0, 0, 0}}};
  const double edge = domain.edge();
  std::array<std::vector<std::array<double, 3>>, 3> spans;  // per axis: {lo, hi, shift}
  for (int a = 0; a < 3; ++a) {
    const double origin = domain.cube.origin[a];
    const double first = std::floor((load.lo[a] - origin) / edge);
    const double last = std::floor((load.hi[a] - origin) / edge);
    for (double image = first; image <= last; ++image) {
      const double lo = std::max(load.lo[a] - image * edge, origin);
      const double hi = std::min(load.hi[a] - image * edge, origin + edge);
      if (lo < hi) spans[static_cast<std::size_t>(a)].push_back({lo, hi, image * edge});
    }
  }
  std::vector<Piece> pieces;
  for (const auto& x : spans[0]) {
    for (const auto& y : spans[1]) {
      for (const auto& z : spans[2]) {
        pieces.push_back(Piece{Box{{x[0], y[0], z[0]}, {x[1], y[1], z[1]}}, {x[2], y[2], z[2]}});
      }
    }
  }
  return pieces;
}

// Whether the sphere of `radius` around `p` lies inside `load`, or reaches
// outside it only past the data's edge of a non-periodic domain.
bool SphereInsideLoad(const Vec3& p, double radius, const Box& load, const Domain& domain) {
  if (!std::isfinite(radius)) return false;
  const double r = radius * (1 + kRoom);
  for (int a = 0; a < 3; ++a) {
    const bool low_edge = !domain.periodic && load.lo[a] <= domain.box.lo[a];
    const bool high_edge = !domain.periodic && load.hi[a] >= domain.box.hi[a];
    if (!(low_edge || p[a] - r >= load.lo[a])) return false;
    if (!(high_edge || p[a] + r <= load.hi[a])) return false;
  }
  return true;
}

// Particle counts on the count grid over the domain's cube, summed into an
// octree of levels 0 .. kCountGridBits.
class CountPyramid {
 public:
  explicit CountPyramid(const Domain& domain) : domain_(domain) {
    for (int level = 0; level <= kCountGridBits; ++level) {
      const std::size_t side = std::size_t{1} << level;
      levels_.emplace_back(side * side * side, 0);
    }
  }

  void Add(const double* p) { ++levels_.back()[CellIndex(p)]; }
  // The counts on the grid itself, before Finish (to sum several processes').
  std::span<std::uint64_t> grid() { return levels_.back(); }

  void Finish() {
    for (int level = kCountGridBits; level > 0; --level) {
      const std::size_t side = std::size_t{1} << level;
      auto& fine = levels_[static_cast<std::size_t>(level)];
      auto& coarse = levels_[static_cast<std::size_t>(level - 1)];
      for (std::size_t z = 0; z < side; ++z) {
        for (std::size_t y = 0; y < side; ++y) {
          for (std::size_t x = 0; x < side; ++x) {
            coarse[Index(x / 2, y / 2, z / 2, side / 2)] += fine[Index(x, y, z, side)];
          }
        }
      }
    }
  }

  std::uint64_t Count(int level, std::size_t x, std::size_t y, std::size_t z) const {
    return levels_[static_cast<std::size_t>(level)][Index(x, y, z, std::size_t{1} << level)];
  }

  // The particles in the count cells that `box` (inside the domain) touches.
  std::uint64_t CountIn(const Box& box) const {
    std::array<std::size_t, 3> first{}, last{};
    for (int a = 0; a < 3; ++a) {
      first[static_cast<std::size_t>(a)] = Cell(box.lo[a], a);
      last[static_cast<std::size_t>(a)] = Cell(std::nextafter(box.hi[a], -kInfinity), a);
    }
    std::uint64_t sum = 0;
    for (std::size_t z = first[2]; z <= last[2]; ++z) {
      for (std::size_t y = first[1]; y <= last[1]; ++y) {
        for (std::size_t x = first[0]; x <= last[0]; ++x) sum += levels_.back()[Index(x, y, z, kCountGridSide)];
      }
    }
    return sum;
  }

 private:
  static std::size_t Index(std::size_t x, std::size_t y, std::size_t z, std::size_t side) {
    return x + side * (y + side * z);
  }
  std::size_t Cell(double coordinate, int axis) const {
    const double t = (coordinate - domain_.cube.origin[static_cast<std::size_t>(axis)]) / domain_.edge();
    const double cell = std::floor(t * kCountGridSide);
    return static_cast<std::size_t>(std::clamp(cell, 0.0, static_cast<double>(kCountGridSide - 1)));
  }
  std::size_t CellIndex(const double* p) const { return Index(Cell(p[0], 0), Cell(p[1], 1), Cell(p[2], 2), kCountGridSide); }

  const Domain& domain_;
  std::vector<std::vector<std::uint64_t>> levels_;
};

class SmoothingPass {
 public:
  SmoothingPass(ParticleSource& source, const SmoothingPassOptions& options, SmoothingPassReport& report)
      : source_(source),
        options_(options),
        report_(report),
        budget_(options.memory_budget ? options.memory_budget : kDefaultBudget),
        capacity_(std::max<std::uint64_t>(budget_ / kBytesPerLoadedPoint, 1)),
        region_most_(std::max<std::uint64_t>(capacity_ / 4, 1)),
        threads_(ResolveThreadCount(static_cast<int>(options.threads))),
        group_(options.group != nullptr && options.group->size() > 1 ? options.group : nullptr),
        rank_(group_ ? static_cast<unsigned>(group_->rank()) : 0),
        ranks_(group_ ? static_cast<unsigned>(group_->size()) : 1) {
    if (options.neighbours < 1) {
      throw Error::InvalidArgument("the number of neighbours must be at least 1, not " +
                                   std::to_string(options.neighbours));
    }
    if (!(options.box_size >= 0) || !std::isfinite(options.box_size)) {
      throw Error::InvalidArgument("smoothing lengths: the periodic box size must be finite and >= 0, not " +
                                   std::to_string(options.box_size));
    }
    domain_.periodic = options.box_size > 0;
    if (domain_.periodic) {
      domain_.cube = Cube{options.box_origin, options.box_size, true};
      domain_.cube.Validate();
      for (int a = 0; a < 3; ++a) {
        domain_.box.lo[a] = options.box_origin[a];
        domain_.box.hi[a] = options.box_origin[a] + options.box_size;
      }
    }
  }

  std::unique_ptr<SmoothingLengthTable> Run() {
    const std::uint64_t total = source_.header().total_count;
    if (total == 0) throw Error::BadInput(SourceName(), "the snapshot holds no particles");
    table_ = std::make_unique<SmoothingLengthTable>(total, budget_, options_.temp_dir);
    report_.particles = total;
    neighbours_ = static_cast<int>(std::min<std::uint64_t>(static_cast<std::uint64_t>(options_.neighbours), total));
    if (!options_.quiet && ranks_ == 1) progress_ = std::make_unique<Progress>("smoothing", total, "points");

    std::vector<Unresolved> unresolved;
    if (ranks_ > 1) {
      SearchShare(total, unresolved);
    } else if (total * kBytesPerLoadedPoint <= budget_) {
      Task whole;
      if (domain_.periodic) {
        whole.region = domain_.box;
        const double margin = std::min(Margin(total, std::pow(domain_.edge(), 3)), domain_.edge());
        whole.load = Widen(domain_.box, margin);
      }
      whole.pieces = PiecesOf(whole.load, domain_);
      std::vector<Task> tasks;
      tasks.push_back(std::move(whole));
      report_.regions = 1;
      LoadInMemory(tasks, /*first_read=*/true);
      Search(tasks[0], unresolved);
    } else {
      SearchOutOfCore(unresolved);
    }
    report_.searched_again = unresolved.size();
    SearchAgain(std::move(unresolved));
    if (found_) DeliverFoundLengths();
    if (progress_) progress_->Finish();
    source_.Rewind();
    return std::move(table_);
  }

 private:
  std::string SourceName() const {
    const auto& files = source_.header().files;
    return files.empty() ? std::string("the snapshot") : files.front();
  }

  // Twice the mean spacing of k particles among `count` in `volume`.
  double Margin(std::uint64_t count, double volume) const {
    return 2.0 * std::cbrt(static_cast<double>(neighbours_) * volume / static_cast<double>(std::max<std::uint64_t>(count, 1)));
  }

  static Box Widen(const Box& box, double margin) {
    Box out = box;
    for (int a = 0; a < 3; ++a) {
      out.lo[a] -= margin;
      out.hi[a] += margin;
    }
    return out;
  }

  // Reads the source once, handing each particle (wrapped into a periodic
  // box) and its ordinal to `visit`. On the first read also checks the count
  // and keeps the snapshot's own smoothing lengths. Shared, each process
  // reads its share of the batches and keeps the lengths of those; with
  // `wanted` (every process's boxes: what its loads hold), each particle goes
  // to `visit` on every process one of whose boxes holds it, else only to
  // the one that read it.
  template <typename Visit>
  void ReadSource(bool first_read, Visit visit, const std::vector<std::vector<Box>>* wanted = nullptr) {
    source_.Rewind();
    ++report_.reads;
    ParticleChunk chunk;
    std::uint64_t ordinal = 0;
    float* table = table_->data();
    std::optional<Router> router;
    if (wanted != nullptr) router.emplace(*wanted, domain_);
    std::vector<std::vector<SharedParticle>> outgoing(ranks_);
    bool read_all = false;
    for (std::uint64_t batch = 0;;) {
      // On to this process's next batch, past the others' (not read where
      // the reader can seek).
      bool got = false;
      while (!read_all && !got) {
        if (group_ && batch == batch_starts_.size()) batch_starts_.push_back(ordinal);
        if (batch % ranks_ != rank_) {
          const std::uint64_t skipped = source_.Skip();
          if (ordinal + skipped > table_->size()) TooMany();
          ordinal += skipped;
          read_all = skipped == 0;
        } else {
          got = source_.Next(chunk);
          read_all = !got;
        }
        if (!read_all) ++batch;
      }
      if (got) {
        const std::size_t n = chunk.size();
        if (ordinal + n > table_->size()) TooMany();
        const bool has_given = chunk.has_smoothing();
        for (std::size_t i = 0; i < n; ++i) {
          double p[3] = {chunk.position[3 * i], chunk.position[3 * i + 1], chunk.position[3 * i + 2]};
          if (domain_.periodic) domain_.cube.Wrap(p);
          const bool given = has_given && chunk.smoothing[i] > 0;
          if (first_read && given) {
            table[ordinal + i] = chunk.smoothing[i];
            ++report_.given;
          }
          if (router) {
            router->Route(p, [&](unsigned to) {
              outgoing[to].push_back({{p[0], p[1], p[2]}, (ordinal + i) | (given ? kGivenBit : 0)});
            });
          } else {
            visit(ordinal + i, p, given);
          }
        }
        ordinal += n;
      }
      if (router) {
        if (ExchangeRound(outgoing, read_all, visit)) break;
      } else if (read_all) {
        break;
      }
    }
    if (ordinal != table_->size()) {
      throw Error::BadInput(SourceName(), "the snapshot gave " + std::to_string(ordinal) +
                                              " particles where its header declares " +
                                              std::to_string(table_->size()));
    }
    if (first_read && progress_) progress_->Add(report_.given);
  }

  // One round of a shared read: each process's particles to those that want
  // them, which visit what they receive. Returns whether every process has
  // read all of its share (each message says whether its sender has).
  template <typename Visit>
  bool ExchangeRound(std::vector<std::vector<SharedParticle>>& outgoing, bool read_all, Visit& visit) {
    std::vector<Bytes> messages(ranks_);
    for (unsigned q = 0; q < ranks_; ++q) {
      const std::uint64_t done = read_all ? 1 : 0;
      Bytes& message = messages[q];
      message.resize(sizeof done + outgoing[q].size() * sizeof(SharedParticle));
      std::memcpy(message.data(), &done, sizeof done);
      if (!outgoing[q].empty()) {
        std::memcpy(message.data() + sizeof done, outgoing[q].data(), outgoing[q].size() * sizeof(SharedParticle));
      }
      outgoing[q].clear();
    }
    bool all_done = true;
    for (const Bytes& message : group_->Exchange(messages)) {
      std::uint64_t done = 0;
      if (message.size() < sizeof done || (message.size() - sizeof done) % sizeof(SharedParticle) != 0) {
        throw Error::Corruption(SourceName(), "a malformed message of the shared smoothing pass");
      }
      std::memcpy(&done, message.data(), sizeof done);
      all_done = all_done && done == 1;
      const std::size_t count = (message.size() - sizeof done) / sizeof(SharedParticle);
      for (std::size_t k = 0; k < count; ++k) {
        SharedParticle particle;
        std::memcpy(&particle, message.data() + sizeof done + k * sizeof particle, sizeof particle);
        const std::uint64_t ordinal = particle.ordinal & ~kGivenBit;
        if (ordinal >= table_->size()) throw Error::Corruption(SourceName(), "a shared particle past the snapshot's count");
        visit(ordinal, particle.position, (particle.ordinal & kGivenBit) != 0);
      }
    }
    return all_done;
  }

  [[noreturn]] void TooMany() const {
    throw Error::BadInput(SourceName(), "the snapshot gave more particles than its header declares (" +
                                            std::to_string(table_->size()) + ")");
  }

  // Loads every task's particles (and the first round's queries) from one
  // read of the source.
  void LoadInMemory(std::vector<Task>& tasks, bool first_read, const std::vector<std::vector<Box>>* wanted = nullptr) {
    ReadSource(first_read, [&](std::uint64_t ordinal, const double* p, bool given) {
      for (Task& task : tasks) {
        if (!task.explicit_queries && !given && task.region.Contains(p)) {
          task.queries.push_back({ordinal, {p[0], p[1], p[2]}});
        }
        for (const Piece& piece : task.pieces) {
          if (!piece.box.Contains(p)) continue;
          for (int a = 0; a < 3; ++a) task.positions.push_back(p[a] + piece.shift[a]);
        }
      }
    }, wanted);
  }

  // Searches the task's queries against its load; exact radii go into the
  // table, the others into `unresolved`. Frees the task's memory.
  void Search(Task& task, std::vector<Unresolved>& unresolved) {
    SortSpatially(task);
    const NeighbourRadii radii(task.positions, task.block_begins, threads_);
    Mutex mutex;  // guards unresolved and found_
    float* table = table_->data();
    ParallelForDynamic(task.queries.size(), threads_, 1024, [&](std::size_t begin, std::size_t end) {
      std::vector<Unresolved> local;
      std::vector<FoundLength> found;  // shared: for the processes that read the particles
      double bound = kInfinity;  // the previous query's radius plus the step to this one
      for (std::size_t q = begin; q < end; ++q) {
        const Query& query = task.queries[q];
        if (q > begin) bound += Distance(task.queries[q - 1].position, query.position);
        const double radius = radii.Radius(query.position.data(), neighbours_, task.query_blocks[q], bound);
        bound = radius;
        if (!SphereInsideLoad(query.position, radius, task.load, domain_)) {
          Vec3 p = query.position;
          if (domain_.periodic) domain_.cube.Wrap(p.data());
          local.push_back({query.ordinal, p, radius});
        } else if (found_) {
          found.push_back({query.ordinal, static_cast<float>(radius)});
        } else {
          table[query.ordinal] = static_cast<float>(radius);
        }
      }
      if (progress_) progress_->Add(end - begin - local.size());
      ThrowIfCancelled();  // also when quiet, without a progress line
      if (local.empty() && found.empty()) return;
      MutexLock lock(mutex);
      unresolved.insert(unresolved.end(), local.begin(), local.end());
      for (const FoundLength& f : found) found_->Add(f);
      found_count_ += found.size();
    });
    if (!task.explicit_queries) report_.searched += task.queries.size();
    Release(task.positions);
    Release(task.block_begins);
    Release(task.query_blocks);
    Release(task.queries);
  }

  // Puts the loaded particles and the queries in Morton order, so that
  // consecutive searches walk the same nodes of the tree and read nearby
  // points (in the order of a snapshot's files most of them missed the
  // cache: measured 2.5x slower on 2 x 10^6 clustered particles), and so
  // that NeighbourRadii's blocks of consecutive points are compact.
  void SortSpatially(Task& task) const {
    const std::size_t n = task.positions.size() / 3;
    if (n == 0) {
      task.query_blocks.assign(task.queries.size(), 0);
      return;
    }
    Vec3 lo{kInfinity, kInfinity, kInfinity}, hi{-kInfinity, -kInfinity, -kInfinity};
    for (std::size_t i = 0; i < n; ++i) {
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], task.positions[3 * i + a]);
        hi[a] = std::max(hi[a], task.positions[3 * i + a]);
      }
    }
    const double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-300});
    const double scale = static_cast<double>((1 << 21) - 1) / extent;
    const auto key = [&](const double* p) {
      std::uint64_t code = 0;
      for (int a = 0; a < 3; ++a) {
        const double t = std::clamp((p[a] - lo[a]) * scale, 0.0, static_cast<double>((1 << 21) - 1));
        code |= SpreadBits3(static_cast<std::uint64_t>(t)) << a;
      }
      return code;
    };
    std::vector<Keyed> order = MortonOrder(n, [&](std::size_t i) { return key(&task.positions[3 * i]); });
    std::vector<double> sorted(3 * n);
    ParallelFor(n, threads_, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        for (int a = 0; a < 3; ++a) sorted[3 * i + a] = task.positions[3 * std::size_t{order[i].second} + a];
      }
    });
    task.positions = std::move(sorted);
    const std::size_t block_points = n / (kBlocksPerThread * static_cast<std::size_t>(threads_));
    task.block_begins = CellBlocks(order, std::max(kMinBlockPoints, block_points));
    std::vector<std::uint64_t> block_first_keys;
    for (const std::size_t begin : task.block_begins) block_first_keys.push_back(order[begin].first);
    Release(order);
    const std::vector<Keyed> query_order =
        MortonOrder(task.queries.size(), [&](std::size_t q) { return key(task.queries[q].position.data()); });
    std::vector<Query> queries(task.queries.size());
    ParallelFor(queries.size(), threads_, [&](std::size_t begin, std::size_t end) {
      for (std::size_t q = begin; q < end; ++q) queries[q] = task.queries[query_order[q].second];
    });
    task.queries = std::move(queries);
    // Both in key order: a query's block is the last to start at or below
    // its key.
    task.query_blocks.resize(task.queries.size());
    std::size_t block = 0;
    for (std::size_t q = 0; q < query_order.size(); ++q) {
      while (block + 1 < block_first_keys.size() && block_first_keys[block + 1] <= query_order[q].first) ++block;
      task.query_blocks[q] = static_cast<std::uint32_t>(block);
    }
  }

  // The starts of blocks of whole octree cells of the sorted keys: a cell
  // of more than `most` points is cut into its octants (down to the finest
  // level), then consecutive cells are merged while they hold at most
  // `most` together. Cells are cubes apart from one another, so a search
  // rarely looks beyond its own block.
  static std::vector<std::size_t> CellBlocks(const std::vector<Keyed>& sorted, std::size_t most) {
    std::vector<std::pair<std::size_t, std::size_t>> cells;  // [begin, end)
    const auto cut = [&](const auto& self, std::size_t begin, std::size_t end, int level) -> void {
      if (end - begin <= most || level >= 21) {
        cells.emplace_back(begin, end);
        return;
      }
      const int shift = 63 - 3 * (level + 1);
      const std::uint64_t parent = sorted[begin].first >> (shift + 3);
      std::size_t child_begin = begin;
      for (std::uint64_t octant = 0; octant < 8; ++octant) {
        const std::uint64_t next_key = ((parent << 3) + octant + 1) << shift;
        const std::size_t child_end = static_cast<std::size_t>(
            std::lower_bound(sorted.begin() + static_cast<std::ptrdiff_t>(child_begin),
                             sorted.begin() + static_cast<std::ptrdiff_t>(end), Keyed{next_key, 0}) - sorted.begin());
        if (child_end > child_begin) self(self, child_begin, child_end, level + 1);
        child_begin = child_end;
      }
    };
    if (!sorted.empty()) cut(cut, 0, sorted.size(), 0);
    std::vector<std::size_t> begins;
    std::size_t held = most;
    for (const auto& [begin, end] : cells) {
      if (held + (end - begin) > most) {
        begins.push_back(begin);
        held = 0;
      }
      held += end - begin;
    }
    return begins;
  }

  // The indices [0, n) with their keys, ordered by key_of(i) (a Morton code
  // of 63 bits), on the pass's threads: the items are dealt into buckets by
  // their keys' top bits, then each bucket is sorted alone.
  template <typename KeyOf>
  std::vector<Keyed> MortonOrder(std::size_t n, KeyOf key_of) const {
    constexpr int kBucketBits = 12;
    constexpr int kShift = 63 - kBucketBits;
    constexpr std::size_t kBuckets = std::size_t{1} << kBucketBits;
    std::vector<Keyed> keyed(n);
    const int threads = std::max(1, std::min<int>(threads_, static_cast<int>(n / 65536) + 1));
    const auto ranges = static_cast<std::size_t>(threads);
    std::vector<std::vector<std::size_t>> counts(ranges, std::vector<std::size_t>(kBuckets + 1, 0));
    // Range r of the items is [n r / ranges, n (r + 1) / ranges).
    const auto for_each_range = [&](const auto& body) {
      ParallelFor(ranges, threads, [&](std::size_t first, std::size_t last) {
        for (std::size_t r = first; r < last; ++r) body(r, n * r / ranges, n * (r + 1) / ranges);
      }, 1);
    };
    std::vector<Keyed> unsorted(n);
    for_each_range([&](std::size_t r, std::size_t begin, std::size_t end) {
      std::vector<std::size_t>& count = counts[r];
      for (std::size_t i = begin; i < end; ++i) {
        unsorted[i] = {key_of(i), static_cast<std::uint32_t>(i)};
        ++count[(unsorted[i].first >> kShift) + 1];
      }
    });
    // Each range's first slot in each bucket: buckets in order, ranges in
    // order within a bucket.
    std::vector<std::size_t> bucket_begin(kBuckets + 1, 0);
    std::size_t at = 0;
    for (std::size_t b = 0; b < kBuckets; ++b) {
      bucket_begin[b] = at;
      for (auto& count : counts) {
        const std::size_t c = count[b + 1];
        count[b + 1] = at;
        at += c;
      }
    }
    bucket_begin[kBuckets] = at;
    for_each_range([&](std::size_t r, std::size_t begin, std::size_t end) {
      std::vector<std::size_t>& next = counts[r];
      for (std::size_t i = begin; i < end; ++i) keyed[next[(unsorted[i].first >> kShift) + 1]++] = unsorted[i];
    });
    Release(unsorted);
    ParallelForDynamic(kBuckets, threads, 16, [&](std::size_t begin, std::size_t end) {
      for (std::size_t b = begin; b < end; ++b) {
        std::sort(keyed.begin() + static_cast<std::ptrdiff_t>(bucket_begin[b]),
                  keyed.begin() + static_cast<std::ptrdiff_t>(bucket_begin[b + 1]));
      }
    });
    return keyed;
  }

  // Step 1 to 3 when the particles do not fit in the budget together.
  void SearchOutOfCore(std::vector<Unresolved>& unresolved) {
    std::vector<Task> tasks = CountAndCutRegions(region_most_);
    report_.spilled = true;
    SearchSpilled(tasks, unresolved);
  }

  // Steps 1 and 2's regions: the bounds found (in a non-periodic snapshot),
  // the particles counted on the grid, and its octree cut into regions of at
  // most `most` particles, in depth-first order.
  std::vector<Task> CountAndCutRegions(std::uint64_t most) {
    if (!domain_.periodic) FindBounds();
    pyramid_ = std::make_unique<CountPyramid>(domain_);
    CountPyramid& counts = *pyramid_;
    ReadSource(/*first_read=*/true, [&](std::uint64_t, const double* p, bool) { counts.Add(p); });
    if (group_) group_->Sum(counts.grid());
    counts.Finish();
    std::vector<Task> tasks;
    CutRegions(counts, most, 0, 0, 0, 0, tasks);
    report_.regions = tasks.size();
    return tasks;
  }

  // Steps 1 to 3 of one part of several: the regions cut as out of core
  // but at least kRegionsPerPart a part, and only this part's searched,
  // from memory where their loads fit the capacity together.
  void SearchShare(std::uint64_t total, std::vector<Unresolved>& unresolved) {
    std::vector<Task> tasks = CountAndCutRegions(
        std::max<std::uint64_t>(1, std::min(region_most_, total / (std::uint64_t{ranks_} * kRegionsPerPart))));
    // Regions come in depth-first order: a part takes those whose middle
    // particle falls in its share of the particles.
    std::vector<std::vector<Task>> shares(ranks_);
    std::uint64_t before = 0;
    for (Task& task : tasks) {
      const std::uint64_t middle = before + task.count / 2;
      before += task.count;
      const std::uint64_t part = std::min<std::uint64_t>(middle * ranks_ / total, ranks_ - 1);
      shares[part].push_back(std::move(task));
    }
    std::vector<std::vector<Box>> wanted;
    for (const std::vector<Task>& share : shares) wanted.push_back(LoadBoxes(share));
    std::vector<Task>& mine = shares[rank_];
    std::uint64_t own = 0, load = 0;
    for (const Task& task : mine) {
      own += task.count;
      load += task.estimate;
    }
    if (!options_.quiet) progress_ = std::make_unique<Progress>("smoothing (this rank's share)", own, "points");
    found_temp_.emplace(TempParent(), "octocosm-smoothing-found");
    found_ = std::make_unique<RecordFileWriter<FoundLength>>(found_temp_->path() + "/found", "the lengths found");
    if (load <= capacity_) {
      LoadInMemory(mine, /*first_read=*/false, &wanted);
      for (Task& task : mine) Search(task, unresolved);
    } else {
      report_.spilled = true;
      SearchSpilled(mine, unresolved, &wanted);
    }
  }

  void FindBounds() {
    Vec3 lo{kInfinity, kInfinity, kInfinity}, hi{-kInfinity, -kInfinity, -kInfinity};
    ReadSource(/*first_read=*/false, [&](std::uint64_t, const double* p, bool) {
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], p[a]);
        hi[a] = std::max(hi[a], p[a]);
      }
    });
    if (group_) {
      std::array<std::uint64_t, 6> most{};
      for (int a = 0; a < 3; ++a) {
        most[static_cast<std::size_t>(a)] = ~Ordered(lo[a]);
        most[static_cast<std::size_t>(a + 3)] = Ordered(hi[a]);
      }
      group_->Max(most);
      for (int a = 0; a < 3; ++a) {
        lo[a] = FromOrdered(~most[static_cast<std::size_t>(a)]);
        hi[a] = FromOrdered(most[static_cast<std::size_t>(a + 3)]);
      }
    }
    domain_.cube = Cube::FromBounds(lo, hi);
    for (int a = 0; a < 3; ++a) {
      domain_.box.lo[a] = lo[a];
      domain_.box.hi[a] = std::nextafter(hi[a], kInfinity);
    }
  }

  // Cuts the count octree into regions of at most `most` particles each (a
  // single count cell may hold more: it is not cut).
  void CutRegions(const CountPyramid& counts, std::uint64_t most, int level, std::size_t x, std::size_t y,
                  std::size_t z, std::vector<Task>& tasks) {
    const std::uint64_t count = counts.Count(level, x, y, z);
    if (count == 0) return;
    if (count > most && level < kCountGridBits) {
      for (int octant = 0; octant < 8; ++octant) {
        CutRegions(counts, most, level + 1, 2 * x + (octant & 1), 2 * y + ((octant >> 1) & 1),
                   2 * z + ((octant >> 2) & 1), tasks);
      }
      return;
    }
    const double edge = domain_.edge() / static_cast<double>(std::size_t{1} << level);
    Task task;
    task.count = count;
    const std::array<std::size_t, 3> cell{x, y, z};
    for (int a = 0; a < 3; ++a) {
      task.region.lo[a] = domain_.cube.origin[a] + edge * static_cast<double>(cell[static_cast<std::size_t>(a)]);
      task.region.hi[a] = task.region.lo[a] + edge;
      // The cube's last cells reach past the data; a non-periodic region on
      // the domain's upper face must hold the particles on it.
      if (cell[static_cast<std::size_t>(a)] + 1 == (std::size_t{1} << level)) {
        task.region.hi[a] = domain_.periodic ? domain_.box.hi[a] : kInfinity;
      }
      if (cell[static_cast<std::size_t>(a)] == 0 && !domain_.periodic) task.region.lo[a] = -kInfinity;
    }
    const double margin = std::min(Margin(count, edge * edge * edge), edge);
    task.load = Widen(task.region, margin);
    task.pieces = PiecesOf(task.load, domain_);
    task.estimate = Estimate(task.pieces);
    tasks.push_back(std::move(task));
  }

  std::uint64_t Estimate(const std::vector<Piece>& pieces) const {
    std::uint64_t sum = 0;
    for (const Piece& piece : pieces) {
      Box inside = piece.box;
      for (int a = 0; a < 3; ++a) {
        inside.lo[a] = std::max(inside.lo[a], domain_.box.lo[a]);
        inside.hi[a] = std::min(inside.hi[a], domain_.box.hi[a]);
        if (!(inside.lo[a] < inside.hi[a])) inside.hi[a] = inside.lo[a];
      }
      bool empty = false;
      for (int a = 0; a < 3; ++a) empty = empty || !(inside.lo[a] < inside.hi[a]);
      if (!empty) sum += pyramid_->CountIn(inside);
    }
    return sum;
  }

  // Groups tasks, in order, into batches whose loads fit the capacity
  // together (a task larger than the capacity goes alone).
  std::vector<std::vector<Task>> Batches(std::vector<Task> tasks) const {
    std::vector<std::vector<Task>> batches;
    std::uint64_t held = 0;
    for (Task& task : tasks) {
      if (batches.empty() || held + task.estimate > capacity_) {
        batches.emplace_back();
        held = 0;
      }
      held += task.estimate;
      batches.back().push_back(std::move(task));
    }
    return batches;
  }

  // Out of core, the particles do not fit together: one read writes each particle into the file of
  // every task whose load holds it; then each task is read back and searched.
  void SearchSpilled(std::vector<Task>& tasks, std::vector<Unresolved>& unresolved,
                     const std::vector<std::vector<Box>>* wanted = nullptr) {
    TempDirectory temp(TempParent(), "octocosm-smoothing");
    // Which tasks' pieces touch each cell of a coarse lookup grid.
    constexpr int kLookupBits = 5;
    constexpr std::size_t kSide = std::size_t{1} << kLookupBits;
    std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> lookup(kSide * kSide * kSide);
    const auto cell_of = [&](double coordinate, int a) {
      const double t = (coordinate - domain_.cube.origin[static_cast<std::size_t>(a)]) / domain_.edge();
      return static_cast<std::size_t>(std::clamp(std::floor(t * kSide), 0.0, static_cast<double>(kSide - 1)));
    };
    for (std::uint32_t t = 0; t < tasks.size(); ++t) {
      for (std::uint32_t k = 0; k < tasks[t].pieces.size(); ++k) {
        const Box& b = tasks[t].pieces[k].box;
        std::array<std::size_t, 3> first{}, last{};
        for (int a = 0; a < 3; ++a) {
          first[static_cast<std::size_t>(a)] = cell_of(std::max(b.lo[a], domain_.box.lo[a]), a);
          last[static_cast<std::size_t>(a)] = cell_of(std::min(b.hi[a], domain_.box.hi[a]), a);
        }
        for (std::size_t z = first[2]; z <= last[2]; ++z) {
          for (std::size_t y = first[1]; y <= last[1]; ++y) {
            for (std::size_t x = first[0]; x <= last[0]; ++x) lookup[x + kSide * (y + kSide * z)].push_back({t, k});
          }
        }
      }
    }
    std::vector<std::unique_ptr<RecordFileWriter<SpilledParticle>>> writers;
    for (std::size_t t = 0; t < tasks.size(); ++t) {
      writers.push_back(std::make_unique<RecordFileWriter<SpilledParticle>>(
          temp.path() + "/region-" + std::to_string(t), "a smoothing-length region", 2048));
    }
    ReadSource(/*first_read=*/false, [&](std::uint64_t ordinal, const double* p, bool given) {
      const auto& candidates = lookup[cell_of(p[0], 0) + kSide * (cell_of(p[1], 1) + kSide * cell_of(p[2], 2))];
      for (const auto& [t, k] : candidates) {
        const Piece& piece = tasks[t].pieces[k];
        if (!piece.box.Contains(p)) continue;
        const bool query = !given && piece.shift == Vec3{0, 0, 0} && tasks[t].region.Contains(p);
        writers[t]->Add(SpilledParticle{{p[0] + piece.shift[0], p[1] + piece.shift[1], p[2] + piece.shift[2]},
                                        ordinal | (query ? kQueryBit : 0)});
      }
    }, wanted);
    for (auto& writer : writers) writer->Close();
    writers.clear();
    for (std::size_t t = 0; t < tasks.size(); ++t) {
      const std::string path = temp.path() + "/region-" + std::to_string(t);
      {
        RecordFileReader<SpilledParticle> reader(path, "a smoothing-length region", 2048);
        SpilledParticle particle;
        while (reader.Next(particle)) {
          for (int a = 0; a < 3; ++a) tasks[t].positions.push_back(particle.position[a]);
          if (particle.ordinal & kQueryBit) {
            tasks[t].queries.push_back({particle.ordinal & ~kQueryBit,
                                        {particle.position[0], particle.position[1], particle.position[2]}});
          }
        }
      }
      fs::remove(path);
      Search(tasks[t], unresolved);
    }
  }

  std::string TempParent() const {
    if (!options_.temp_dir.empty()) return options_.temp_dir;
    const char* env = std::getenv("TMPDIR");
    return env && *env ? env : "/tmp";
  }

  // Step 4: each unresolved particle against everything inside its sphere,
  // in groups whose loads fit the capacity, one read of the source per batch.
  // Shared, every process reads as many times as the one with the most
  // batches, each wanting its own batch's loads.
  void SearchAgain(std::vector<Unresolved> unresolved) {
    for (int round = 0;; ++round) {
      std::uint64_t left = unresolved.size();
      if (group_) group_->Sum(std::span<std::uint64_t>(&left, 1));
      if (left == 0) return;
      if (round == 3) {
        throw Error::BadInput(SourceName(), std::to_string(left) +
                                                " particles' neighbours could not be bounded (positions too large "
                                                "for double precision?)");
      }
      std::vector<Task> tasks;
      if (!unresolved.empty()) Group(std::move(unresolved), tasks);
      unresolved.clear();
      std::vector<std::vector<Task>> batches = Batches(std::move(tasks));
      std::uint64_t reads = batches.size();
      if (group_) group_->Max(std::span<std::uint64_t>(&reads, 1));
      batches.resize(static_cast<std::size_t>(reads));
      for (std::vector<Task>& batch : batches) {
        if (group_) {
          const std::vector<std::vector<Box>> wanted = EveryProcessBoxes(LoadBoxes(batch));
          LoadInMemory(batch, /*first_read=*/false, &wanted);
        } else {
          LoadInMemory(batch, /*first_read=*/false);
        }
        for (Task& task : batch) Search(task, unresolved);
      }
    }
  }

  // Shared: every length this process found goes to the process that reads
  // its particle's batch (batch b: process b % size), in rounds of at most
  // kDeliveryRound from each, so that each process's table holds the lengths
  // of its own batches only (the rest of it is never written: in a mapped
  // file, no disk either).
  void DeliverFoundLengths() {
    constexpr std::uint64_t kDeliveryRound = std::uint64_t{1} << 16;
    found_->Close();
    const std::string path = found_temp_->path() + "/found";
    std::uint64_t rounds = (found_count_ + kDeliveryRound - 1) / kDeliveryRound;
    group_->Max(std::span<std::uint64_t>(&rounds, 1));
    const auto reader_of = [&](std::uint64_t ordinal) {
      const auto after = std::upper_bound(batch_starts_.begin(), batch_starts_.end(), ordinal);
      return static_cast<unsigned>(static_cast<std::uint64_t>(after - batch_starts_.begin() - 1) % ranks_);
    };
    RecordFileReader<FoundLength> reader(path, "the lengths found");
    float* table = table_->data();
    for (std::uint64_t round = 0; round < rounds; ++round) {
      std::vector<Bytes> messages(ranks_);
      FoundLength f;
      for (std::uint64_t k = 0; k < kDeliveryRound && reader.Next(f); ++k) {
        Bytes& message = messages[reader_of(f.ordinal)];
        const auto* bytes = reinterpret_cast<const std::uint8_t*>(&f);
        message.insert(message.end(), bytes, bytes + sizeof f);
      }
      for (const Bytes& message : group_->Exchange(messages)) {
        if (message.size() % sizeof(FoundLength) != 0) {
          throw Error::Corruption(SourceName(), "a malformed message of smoothing lengths");
        }
        for (std::size_t at = 0; at < message.size(); at += sizeof(FoundLength)) {
          std::memcpy(&f, message.data() + at, sizeof f);
          if (f.ordinal >= table_->size() || reader_of(f.ordinal) != rank_) {
            throw Error::Corruption(SourceName(), "a smoothing length for a particle this process does not read");
          }
          table[f.ordinal] = f.length;
        }
      }
    }
    found_.reset();
    found_temp_.reset();
  }

  // Every process's `mine`, by process.
  std::vector<std::vector<Box>> EveryProcessBoxes(const std::vector<Box>& mine) const {
    const auto* bytes = reinterpret_cast<const std::uint8_t*>(mine.data());
    const Bytes message(bytes, bytes + mine.size() * sizeof(Box));
    std::vector<std::vector<Box>> wanted;
    for (const Bytes& theirs : group_->Exchange(std::vector<Bytes>(ranks_, message))) {
      if (theirs.size() % sizeof(Box) != 0) throw Error::Corruption(SourceName(), "a malformed message of boxes");
      std::vector<Box>& boxes = wanted.emplace_back(theirs.size() / sizeof(Box));
      if (!boxes.empty()) std::memcpy(boxes.data(), theirs.data(), theirs.size());
    }
    return wanted;
  }

  // The load holding the spheres of `group`: their bounding box, or, when a
  // sphere is unbounded, everything.
  Box SphereBounds(const std::vector<Unresolved>& group) const {
    Box box{{kInfinity, kInfinity, kInfinity}, {-kInfinity, -kInfinity, -kInfinity}};
    for (const Unresolved& u : group) {
      if (!std::isfinite(u.radius)) {
        if (!domain_.periodic) return Box{};
        return Widen(domain_.box, domain_.edge());
      }
      const double r = u.radius * (1 + 4 * kRoom);
      for (int a = 0; a < 3; ++a) {
        box.lo[a] = std::min(box.lo[a], u.position[a] - r);
        box.hi[a] = std::max(box.hi[a], std::nextafter(u.position[a] + r, kInfinity));
      }
    }
    return box;
  }

  // Splits the unresolved particles at the median of their longest axis
  // until each group's load fits the capacity (or is one particle), and
  // makes a task of each group.
  void Group(std::vector<Unresolved> group, std::vector<Task>& tasks) const {
    Task task;
    task.explicit_queries = true;
    task.load = SphereBounds(group);
    task.pieces = PiecesOf(task.load, domain_);
    task.estimate = pyramid_ ? Estimate(task.pieces) : 0;
    if (task.estimate > capacity_ && group.size() > 1) {
      int axis = 0;
      Box extent{{kInfinity, kInfinity, kInfinity}, {-kInfinity, -kInfinity, -kInfinity}};
      for (const Unresolved& u : group) {
        for (int a = 0; a < 3; ++a) {
          extent.lo[a] = std::min(extent.lo[a], u.position[a]);
          extent.hi[a] = std::max(extent.hi[a], u.position[a]);
        }
      }
      for (int a = 1; a < 3; ++a) {
        if (extent.hi[a] - extent.lo[a] > extent.hi[axis] - extent.lo[axis]) axis = a;
      }
      const auto middle = group.begin() + static_cast<std::ptrdiff_t>(group.size() / 2);
      std::nth_element(group.begin(), middle, group.end(), [axis](const Unresolved& a, const Unresolved& b) {
        return a.position[axis] < b.position[axis];
      });
      std::vector<Unresolved> upper(middle, group.end());
      group.erase(middle, group.end());
      Group(std::move(group), tasks);
      Group(std::move(upper), tasks);
      return;
    }
    for (const Unresolved& u : group) task.queries.push_back({u.ordinal, u.position});
    tasks.push_back(std::move(task));
  }

  ParticleSource& source_;
  const SmoothingPassOptions& options_;
  SmoothingPassReport& report_;
  std::uint64_t budget_;
  std::uint64_t capacity_;  // particles held at once
  const std::uint64_t region_most_;  // particles an out-of-core region holds at most: a quarter of the capacity
  int threads_;
  RankGroup* const group_;  // the processes sharing the pass, or null
  const unsigned rank_, ranks_;
  int neighbours_ = kDefaultNeighbours;
  Domain domain_;
  std::unique_ptr<CountPyramid> pyramid_;  // out of core only: estimates what a load holds
  std::unique_ptr<SmoothingLengthTable> table_;
  std::unique_ptr<Progress> progress_;
  // Shared: the ordinal where each batch of the snapshot starts, and the
  // lengths this process found, until they go to the processes that read
  // their batches.
  std::vector<std::uint64_t> batch_starts_;
  std::optional<TempDirectory> found_temp_;
  std::unique_ptr<RecordFileWriter<FoundLength>> found_;
  std::uint64_t found_count_ = 0;
};

class SmoothedSource : public ParticleSource {
 public:
  SmoothedSource(std::unique_ptr<ParticleSource> inner, std::shared_ptr<const SmoothingLengthTable> table)
      : inner_(std::move(inner)), table_(std::move(table)), header_(inner_->header()) {
    header_.has_smoothing = true;
  }

  const SnapshotHeader& header() const override { return header_; }

  bool Next(ParticleChunk& chunk) override {
    if (!inner_->Next(chunk)) return false;
    const std::size_t n = chunk.size();
    if (next_ + n > table_->size()) {
      const auto& files = header().files;
      throw Error::BadInput(files.empty() ? std::string("the snapshot") : files.front(),
                            "the snapshot gave more particles than when its smoothing lengths were computed (" +
                                std::to_string(table_->size()) + ")");
    }
    chunk.smoothing.assign(table_->data() + next_, table_->data() + next_ + n);
    next_ += n;
    return true;
  }

  void Rewind() override {
    inner_->Rewind();
    next_ = 0;
  }
  void SetPositionsOnly(bool positions_only) override { inner_->SetPositionsOnly(positions_only); }

  std::uint64_t Skip() override {
    const std::uint64_t skipped = inner_->Skip();
    next_ += skipped;
    return skipped;
  }

 private:
  std::unique_ptr<ParticleSource> inner_;
  std::shared_ptr<const SmoothingLengthTable> table_;
  SnapshotHeader header_;
  std::uint64_t next_ = 0;
};

}  // namespace

SmoothingLengthTable::SmoothingLengthTable(std::uint64_t size, std::uint64_t memory_budget,
                                           const std::string& temp_dir)
    : size_(size) {
  const std::uint64_t bytes = std::max<std::uint64_t>(size, 1) * sizeof(float);
  if (memory_budget == 0 || bytes <= memory_budget / 4) {
    owned_ = std::make_unique<float[]>(std::max<std::uint64_t>(size, 1));
    data_ = owned_.get();
    return;
  }
  std::string parent = temp_dir;
  if (parent.empty()) {
    const char* env = std::getenv("TMPDIR");
    parent = env && *env ? env : "/tmp";
  }
  std::string path = (fs::path(parent) / "octocosm-smoothing-XXXXXX").string();
  const int fd = ::mkstemp(path.data());
  if (fd < 0) throw IoErrorFromErrno(path, "creating the smoothing-length table", errno);
  ::unlink(path.c_str());
  if (::ftruncate(fd, static_cast<off_t>(bytes)) != 0) {
    const int error = errno;
    ::close(fd);
    throw IoErrorFromErrno(path, "sizing the smoothing-length table (is the disk full?)", error);
  }
  void* map = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  const int error = errno;
  ::close(fd);
  if (map == MAP_FAILED) throw IoErrorFromErrno(path, "mapping the smoothing-length table", error);
  data_ = static_cast<float*>(map);
  mapped_ = true;
}

SmoothingLengthTable::~SmoothingLengthTable() {
  if (mapped_) ::munmap(data_, std::max<std::uint64_t>(size_, 1) * sizeof(float));
}

std::unique_ptr<SmoothingLengthTable> ComputeSmoothingLengths(ParticleSource& source,
                                                              const SmoothingPassOptions& options,
                                                              SmoothingPassReport* report) {
  const auto start = std::chrono::steady_clock::now();
  SmoothingPassReport local;
  SmoothingPassReport& out = report ? *report : local;
  out = {};
  // Neighbours need positions alone (and the snapshot's own lengths).
  const PositionsOnlyReads positions_only(source);
  SmoothingPass pass(source, options, out);
  std::unique_ptr<SmoothingLengthTable> table = pass.Run();
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return table;
}

std::unique_ptr<ParticleSource> WithSmoothingLengths(std::unique_ptr<ParticleSource> inner,
                                                     std::shared_ptr<const SmoothingLengthTable> table) {
  return std::make_unique<SmoothedSource>(std::move(inner), std::move(table));
}

}  // namespace octocosm
