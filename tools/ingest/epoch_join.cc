#include "tools/ingest/epoch_join.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "storage/error.h"

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

SortedEpoch::SortedEpoch(ParticleSource& source, const std::string& temp_prefix, std::size_t run_records,
                         const std::function<void(std::uint64_t)>& on_points)
    : sorter_(temp_prefix, run_records) {
  if (!source.header().has_id) {
    throw Error::InvalidArgument("sorting an epoch by ID needs particle IDs, and " + source.header().files.front() +
                                 " has none");
  }
  has_velocity_ = source.header().has_velocity;
  source.Rewind();
  ParticleChunk chunk;
  while (source.Next(chunk)) {
    bounds_.Add(chunk);
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
  auto reader = sorter_.Open();
  ParticleRecord r{};
  bool first = true;
  std::uint64_t previous = 0;
  while (reader.Next(r)) {
    if (!first && r.key == previous) ++duplicate_ids_;
    previous = r.key;
    first = false;
  }
}

JoinStats JoinedPass(const SortedEpoch& current, const SortedEpoch* next, double box_size, std::size_t batch_points,
                     const std::function<void(const ParticleChunk&)>& consume) {
  JoinStats stats;
  auto cur = current.sorter().Open();
  std::optional<ExternalSorter<ParticleRecord>::Reader> nxt;
  ParticleRecord n{};
  bool have_next = false;
  if (next != nullptr) {
    nxt.emplace(next->sorter().Open());
    have_next = nxt->Next(n);
  }
  ParticleChunk batch;
  const bool velocity = current.has_velocity();
  auto emit = [&] {
    if (batch.size() > 0) consume(batch);
    batch.clear();
  };
  ParticleRecord c{};
  while (cur.Next(c)) {
    while (have_next && n.key < c.key) have_next = nxt->Next(n);
    float offset[3] = {0, 0, 0};
    if (have_next && n.key == c.key) {
      for (int a = 0; a < 3; ++a) {
        double d = n.position[a] - c.position[a];
        if (box_size > 0) d -= box_size * std::nearbyint(d / box_size);
        offset[a] = static_cast<float>(d);
      }
      ++stats.matched;
      have_next = nxt->Next(n);  // duplicates pair up in order
    } else if (next != nullptr) {
      ++stats.missing_in_next;
    }
    for (int a = 0; a < 3; ++a) batch.position.push_back(c.position[a]);
    batch.mass.push_back(c.mass);
    batch.type.push_back(c.type);
    batch.id.push_back(c.key);
    if (velocity) batch.velocity.insert(batch.velocity.end(), c.velocity, c.velocity + 3);
    if (next != nullptr) batch.displacement.insert(batch.displacement.end(), offset, offset + 3);
    if (batch.size() >= batch_points) emit();
  }
  emit();
  return stats;
}

}  // namespace octocosm
