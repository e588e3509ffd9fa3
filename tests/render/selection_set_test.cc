// The GPU's ID set, probed on the CPU exactly as the shader probes it.
#include <gtest/gtest.h>

#include <random>
#include <unordered_set>

#include "base/error.h"
#include "render/selection_set.h"

namespace octocosm {
namespace {

TEST(SelectionSetTest, AMillionIdsAreFoundAndNothingElse) {
  std::mt19937_64 rng(5);
  std::vector<std::uint64_t> ids(1000000);
  for (auto& id : ids) id = rng() >> (id % 2 ? 0 : 40);  // large and small IDs
  ids.push_back(ids[17]);  // duplicates are fine
  const SelectionSet set(ids);
  const std::unordered_set<std::uint64_t> truth(ids.begin(), ids.end());
  EXPECT_EQ(set.size(), truth.size());
  for (std::uint64_t id : ids) ASSERT_TRUE(set.Contains(id));
  for (int k = 0; k < 1000000; ++k) {
    const std::uint64_t probe = rng() >> (k % 3 * 20);
    ASSERT_EQ(set.Contains(probe), truth.count(probe) > 0);
  }
  // Load factor at most one half.
  EXPECT_GE(set.words().size() - 4, 4 * truth.size());
}

TEST(SelectionSetTest, TheEmptySlotMarkerCannotBeSelected) {
  const std::vector<std::uint64_t> ids = {~std::uint64_t{0}};
  EXPECT_THROW(SelectionSet set(ids), Error);
  const SelectionSet empty(std::vector<std::uint64_t>{});
  EXPECT_EQ(empty.size(), 0u);
  EXPECT_FALSE(empty.Contains(0));
}

}  // namespace
}  // namespace octocosm
