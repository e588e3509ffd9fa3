// A batch of particles in absolute coordinates, as input readers produce them
// and the octree builder consumes them. Columns are separate (structure of
// arrays) so that a stage that does not need a column never touches it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace octocosm {

struct ParticleChunk {
  std::vector<double> position;       // x,y,z interleaved: 3 * size(); absolute, in input units
  std::vector<float> velocity;        // 3 * size(), or empty when the input has none
  std::vector<double> mass;           // size(); always filled (from a mass column, a mass table, or 1)
  std::vector<std::uint64_t> id;      // size(), or empty when the input has no IDs
  std::vector<std::uint8_t> type;     // size(); particle type (GADGET PartType), 0 when the format has none
  std::vector<float> displacement;    // 3 * size(), or empty: minimal-image offset to the same ID's next-epoch position

  std::size_t size() const { return mass.size(); }
  bool has_velocity() const { return !velocity.empty(); }
  bool has_id() const { return !id.empty(); }

  void clear() {
    position.clear();
    velocity.clear();
    mass.clear();
    id.clear();
    type.clear();
    displacement.clear();
  }
};

}  // namespace octocosm
