// A batch of particles in absolute coordinates, as input readers produce them
// and the octree builder consumes them. Columns are separate (structure of
// arrays) so that a stage that does not need a column never touches it.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace octocosm {

// The optional columns of three floats per point, which ParticleChunk and
// NodePoints carry alike and every stage treats alike (VectorColumns lists
// them), in the order blocks store them. Each is empty or holds 3 * size()
// values, x,y,z interleaved. The epoch links (all but velocity) come from
// joining a series' epochs by particle ID (ingest/epoch_join.h).
enum class VectorColumn : std::uint8_t {
  kVelocity,          // the particle's velocity, in input units
  kDisplacement,      // minimal-image offset to the same particle's position at the next epoch
  kNextVelocity,      // its velocity at the next epoch
  kPrevDisplacement,  // minimal-image offset to its position at the previous epoch
  kPrevVelocity,      // its velocity at the previous epoch
};
inline constexpr std::size_t kVectorColumnCount = 5;

struct ParticleChunk {
  std::vector<double> position;       // x,y,z interleaved: 3 * size(); absolute, in input units
  std::vector<double> mass;           // size(); always filled (from a mass column, a mass table, or 1)
  std::vector<std::uint64_t> id;      // size(), or empty when the input has no IDs
  std::vector<std::uint8_t> type;     // size(); particle type (GADGET PartType), 0 when the format has none
  // Each particle's smoothing length given from outside (a snapshot's own,
  // or a nearest-neighbour pass's), or empty when none is given: size()
  // values when present. A value > 0 is the radius of the particle's kernel
  // support in input length units, which the octree's leaves keep; 0 means
  // "not given" for that particle, which then gets the leaf's density-grid
  // length like every particle of an input without the column
  // (index/subtree_builder.h). Finite and >= 0: readers reject other
  // values as bad input, the octree builder as an invalid argument.
  std::vector<float> smoothing;
  std::vector<float> velocity;        // the vector columns (VectorColumn): 3 * size() or empty
  std::vector<float> displacement;
  std::vector<float> next_velocity;
  std::vector<float> prev_displacement;
  std::vector<float> prev_velocity;

  std::size_t size() const { return mass.size(); }
  bool has_velocity() const { return !velocity.empty(); }
  bool has_id() const { return !id.empty(); }
  bool has_smoothing() const { return !smoothing.empty(); }

  void clear();
  // Appends every column of `other` to this chunk's, as they are (a column
  // one of them lacks stays as it was in this one).
  void Append(const ParticleChunk& other);
};

// The vector columns of a ParticleChunk or NodePoints (const or not), indexed
// by VectorColumn.
template <typename Points>
auto VectorColumns(Points& points) -> std::array<decltype(&points.velocity), kVectorColumnCount> {
  return {&points.velocity, &points.displacement, &points.next_velocity, &points.prev_displacement,
          &points.prev_velocity};
}

inline void ParticleChunk::clear() {
  position.clear();
  mass.clear();
  id.clear();
  type.clear();
  smoothing.clear();
  for (std::vector<float>* column : VectorColumns(*this)) column->clear();
}

inline void ParticleChunk::Append(const ParticleChunk& other) {
  const auto append = [](auto& to, const auto& from) { to.insert(to.end(), from.begin(), from.end()); };
  append(position, other.position);
  append(mass, other.mass);
  append(id, other.id);
  append(type, other.type);
  append(smoothing, other.smoothing);
  const auto to = VectorColumns(*this);
  const auto from = VectorColumns(other);
  for (std::size_t c = 0; c < to.size(); ++c) append(*to[c], *from[c]);
}

}  // namespace octocosm
