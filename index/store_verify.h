// Verification of a dataset store: every block's checksum and columns, the
// key structure (valid keys, every node's parent present), node capacities,
// the weights of every inner node against its children's, what the dataset
// metadata records of each epoch's tree (points, mass, nodes, leaves, depth)
// against the blocks, and a sample of the ID index against the leaves. The
// manifest's own checksum is checked when the store opens.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace octocosm {

struct VerifyReport {
  std::vector<std::string> faults;  // the first 1000, each naming file, epoch and block
  std::uint64_t blocks_checked = 0;  // blocks that read and decoded
  std::uint32_t epochs = 0;
  bool id_index_checked = false;
};

// Collects every fault instead of stopping at the first; `on_fault` (may be
// empty) sees each as it is found. Throws Error only when the store does not
// open at all (missing, unfinished, manifest or page file headers damaged).
VerifyReport VerifyStore(const std::string& directory, const std::function<void(const std::string&)>& on_fault = {});

}  // namespace octocosm
