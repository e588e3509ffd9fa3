#include "index/cells_below.h"

#include <string>

#include "base/error.h"

namespace octocosm {

CellsBelow::CellsBelow(const Cube& cube, NodeKey node, int level) : cube_(cube), level_(level) {
  if (!node.IsValid() || level < node.level() || level > kMaxLevel) {
    throw Error::InvalidArgument("cells below node " + std::to_string(node.value()) + ": level " +
                                 std::to_string(level) + " is not between the node's and " + std::to_string(kMaxLevel));
  }
  depth_ = level - node.level();
  const CellCoord cell = node.cell();
  corner_[0] = std::uint64_t{cell.x} << depth_;
  corner_[1] = std::uint64_t{cell.y} << depth_;
  corner_[2] = std::uint64_t{cell.z} << depth_;
}

}  // namespace octocosm
