#include "ingest/epoch_join.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <vector>

#include "base/error.h"
#include "ingest/record_file.h"

namespace octocosm {

void Bounds::Add(const ParticleChunk& chunk) {
  for (std::size_t i = 0; i < chunk.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      const double x = chunk.position[3 * i + a];
      lo[a] = std::min(lo[a], x);
      hi[a] = std::max(hi[a], x);
    }
    mass += chunk.mass[i];
  }
  count += chunk.size();
}

namespace {

// The ParticleRecords of a run: all of `run_records`, or with smoothing
// lengths a share that leaves room for as many SmoothingRecords.
std::size_t ParticleRunRecords(const ParticleSource& source, std::size_t run_records) {
  if (!source.header().has_smoothing) return run_records;
  return std::max<std::size_t>(run_records / (sizeof(ParticleRecord) + sizeof(SmoothingRecord)) * sizeof(ParticleRecord), 1);
}

}  // namespace

SortedEpoch::SortedEpoch(ParticleSource& source, const std::string& temp_prefix, std::size_t run_records,
                         const std::function<void(std::uint64_t)>& on_points)
    : sorter_(temp_prefix, ParticleRunRecords(source, run_records)) {
  if (!source.header().has_id) {
    throw Error::InvalidArgument("sorting an epoch by ID needs particle IDs, and " + source.header().files.front() +
                                 " has none");
  }
  has_velocity_ = source.header().has_velocity;
  if (source.header().has_smoothing) {
    smoothing_sorter_ = std::make_unique<ExternalSorter<SmoothingRecord>>(temp_prefix + "-smoothing",
                                                                          ParticleRunRecords(source, run_records));
  }
  source.Rewind();
  ParticleChunk chunk;
  std::vector<SmoothingRecord> smoothing;
  while (source.Next(chunk)) {
    bounds_.Add(chunk);
    if (smoothing_sorter_) {
      if (chunk.smoothing.size() != chunk.size()) {
        throw Error::InvalidArgument("sorting an epoch by ID: a batch of " + source.header().files.front() +
                                     " lacks the smoothing lengths its header announces");
      }
      smoothing.resize(chunk.size());
      for (std::size_t i = 0; i < chunk.size(); ++i) smoothing[i] = SmoothingRecord{chunk.id[i], chunk.smoothing[i]};
      smoothing_sorter_->Add(smoothing);
    }
    for (std::size_t i = 0; i < chunk.size(); ++i) {
      ParticleRecord r{};
      r.key = chunk.id[i];
      for (int a = 0; a < 3; ++a) r.position[a] = chunk.position[3 * i + a];
      r.mass = chunk.mass[i];
      if (has_velocity_) {
        for (int a = 0; a < 3; ++a) r.velocity[a] = chunk.velocity[3 * i + a];
      }
      r.type = chunk.type[i];
      sorter_.Add(r);
    }
    if (on_points) on_points(chunk.size());
  }
  sorter_.Finish();
  if (smoothing_sorter_) smoothing_sorter_->Finish();
  auto reader = sorter_.Open();
  ParticleRecord r{};
  bool first = true;
  std::uint64_t previous = 0;
  while (reader.Next(r)) {
    if (!first && r.key == previous && duplicate_ids_++ == 0) first_duplicate_id_ = r.key;
    previous = r.key;
    first = false;
  }
}

VelocityScaleFit::VelocityScaleFit() : bins_(2 * kBins) {}

void VelocityScaleFit::Add(const double displacement[3], const float velocity[3], const float next_velocity[3]) {
  double dv = 0, vv = 0, dd = 0;
  for (int a = 0; a < 3; ++a) {
    const double vbar = 0.5 * (static_cast<double>(velocity[a]) + next_velocity[a]);
    dv += displacement[a] * vbar;
    vv += vbar * vbar;
    dd += displacement[a] * displacement[a];
  }
  sum_dv_ += dv;
  sum_vv_ += vv;
  sum_dd_ += dd;
  if (!(vv > 0) || dv == 0) return;  // no scale of its own
  const double own_scale = dv / vv;
  if (!std::isfinite(own_scale)) return;
  const int bin = std::clamp(static_cast<int>(std::floor(std::log2(std::fabs(own_scale)) * kBinsPerOctave)) + kBins / 2,
                             0, kBins - 1);
  Bin& b = bins_[static_cast<std::size_t>(bin + (own_scale < 0 ? kBins : 0))];
  b.vv += vv;
  b.dv += dv;
}

std::pair<std::size_t, std::size_t> VelocityScaleFit::InlierBins() const {
  // The heaviest run of three adjacent bins of one sign; its middle is the mode.
  std::size_t mode = 0;
  double heaviest = 0;
  for (std::size_t half = 0; half < 2; ++half) {
    for (std::size_t i = half * kBins + 1; i + 1 < (half + 1) * kBins; ++i) {
      const double weight = bins_[i - 1].vv + bins_[i].vv + bins_[i + 1].vv;
      if (weight > heaviest) {
        heaviest = weight;
        mode = i;
      }
    }
  }
  const std::size_t half_begin = mode < kBins ? 0 : kBins;
  const std::size_t first = std::max(mode, half_begin + kInlierBins) - kInlierBins;
  const std::size_t last = std::min(mode + kInlierBins + 1, half_begin + kBins);
  return {first, last};
}

double VelocityScaleFit::velocity_scale() const {
  if (!Fitted()) return 0;
  const auto [first, last] = InlierBins();
  double dv = 0, vv = 0;
  for (std::size_t i = first; i < last; ++i) {
    dv += bins_[i].dv;
    vv += bins_[i].vv;
  }
  const double s = vv > 0 ? dv / vv : 0;
  return std::isfinite(s) ? s : 0;
}

double VelocityScaleFit::least_squares_scale() const {
  if (!Fitted()) return 0;
  const double s = sum_dv_ / sum_vv_;
  return std::isfinite(s) ? s : 0;
}

double VelocityScaleFit::fit_residual() const {
  if (!Fitted()) return 1;
  // sum |d - s vbar|^2 expanded, clamped against rounding below zero.
  const double s = velocity_scale();
  const double residual = std::max(0.0, sum_dd_ - 2 * s * sum_dv_ + s * s * sum_vv_);
  const double r = std::sqrt(residual / sum_dd_);
  return std::isfinite(r) ? r : 1;
}

double VelocityScaleFit::inlier_fraction() const {
  if (!Fitted()) return 0;
  const auto [first, last] = InlierBins();
  double vv = 0;
  for (std::size_t i = first; i < last; ++i) vv += bins_[i].vv;
  return vv / sum_vv_;
}

namespace {

// One particle's way back to the previous epoch, as the link file holds it.
struct BackLink {
  std::uint64_t id;
  float displacement[3];  // to its position in the previous epoch
  float velocity[3];      // its velocity there
};

constexpr const char* kLinkFile = "an epoch link file";

double Norm(const float* v) {
  const double x = v[0], y = v[1], z = v[2];
  return std::sqrt(x * x + y * y + z * z);
}

void Append3(std::vector<float>& column, const float* values) { column.insert(column.end(), values, values + 3); }

}  // namespace

JoinStats JoinedPass(const SortedEpoch& current, const SortedEpoch* next, const std::string& links_from_previous,
                     const std::string& links_to_next, double box_size, std::size_t batch_points,
                     const std::function<void(const ParticleChunk&)>& consume) {
  JoinStats stats;
  const bool velocity = current.has_velocity();
  auto cur = current.sorter().Open();
  std::optional<ExternalSorter<ParticleRecord>::Reader> nxt;
  std::optional<RecordFileWriter<BackLink>> links_out;
  std::optional<RecordFileReader<BackLink>> links_in;
  ParticleRecord n{};
  bool have_next = false;
  if (next != nullptr) {
    nxt.emplace(next->sorter().Open());
    have_next = nxt->Next(n);
    links_out.emplace(links_to_next, kLinkFile);
  }
  if (!links_from_previous.empty()) links_in.emplace(links_from_previous, kLinkFile);
  std::optional<ExternalSorter<SmoothingRecord>::Reader> smoothing;
  if (current.has_smoothing()) smoothing.emplace(current.smoothing_sorter().Open());
  // A particle of the next epoch that this one lacks: it has no way back.
  auto skip_next = [&] {
    links_out->Add(BackLink{n.key, {0, 0, 0}, {0, 0, 0}});
    ++stats.new_in_next;
    have_next = nxt->Next(n);
  };

  ParticleChunk batch;
  auto emit = [&] {
    if (batch.size() > 0) consume(batch);
    batch.clear();
  };
  ParticleRecord c{};
  while (cur.Next(c)) {
    while (have_next && n.key < c.key) skip_next();
    float offset[3] = {0, 0, 0};
    float next_velocity[3] = {0, 0, 0};
    if (have_next && n.key == c.key) {
      double d[3];
      BackLink back{n.key, {}, {}};
      for (int a = 0; a < 3; ++a) {
        d[a] = n.position[a] - c.position[a];
        if (box_size > 0) d[a] -= box_size * std::nearbyint(d[a] / box_size);
        offset[a] = static_cast<float>(d[a]);
        back.displacement[a] = -offset[a];  // exactly the way forward, reversed
        back.velocity[a] = c.velocity[a];
        next_velocity[a] = n.velocity[a];
      }
      if (velocity) {
        stats.fit.Add(d, c.velocity, n.velocity);
        stats.max_speed_sum = std::max(stats.max_speed_sum, Norm(c.velocity) + Norm(n.velocity));
      }
      stats.max_displacement = std::max(stats.max_displacement, std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
      links_out->Add(back);
      ++stats.matched;
      have_next = nxt->Next(n);  // duplicates pair up in order
    } else if (next != nullptr) {
      ++stats.missing_in_next;
    }
    BackLink back{c.key, {0, 0, 0}, {0, 0, 0}};
    if (links_in && (!links_in->Next(back) || back.id != c.key)) {
      throw Error::Corruption(links_from_previous, "epoch link file out of step with the epoch's particles at ID " +
                                                       std::to_string(c.key));
    }
    for (int a = 0; a < 3; ++a) batch.position.push_back(c.position[a]);
    batch.mass.push_back(c.mass);
    batch.type.push_back(c.type);
    batch.id.push_back(c.key);
    if (smoothing) {
      SmoothingRecord h{};
      if (!smoothing->Next(h) || h.key != c.key) {
        throw std::logic_error("epoch join: the smoothing lengths sorted by ID are out of step with the particles at ID " +
                               std::to_string(c.key));
      }
      batch.smoothing.push_back(h.smoothing);
    }
    if (velocity) Append3(batch.velocity, c.velocity);
    if (next != nullptr) {
      Append3(batch.displacement, offset);
      if (velocity) Append3(batch.next_velocity, next_velocity);
    }
    if (links_in) {
      Append3(batch.prev_displacement, back.displacement);
      if (velocity) Append3(batch.prev_velocity, back.velocity);
    }
    if (batch.size() >= batch_points) emit();
  }
  emit();
  while (have_next) skip_next();
  BackLink extra{};
  if (links_in && links_in->Next(extra)) {
    throw Error::Corruption(links_from_previous, "epoch link file holds more particles than its epoch");
  }
  if (links_out) links_out->Close();
  return stats;
}

}  // namespace octocosm
