#include "storage/block_index_builder.h"

#include <algorithm>
#include <vector>

namespace octocosm {

IndexLayout BuildBlockIndex(std::span<const IndexEntry> sorted_entries, std::uint64_t first_page,
                            std::uint32_t page_size, const IndexPageSink& sink) {
  IndexLayout layout;
  layout.first_page = first_page;
  if (sorted_entries.empty()) return layout;

  std::uint64_t next_page = first_page;
  // Each written page contributes (its first key, its page number) to the
  // level above.
  std::vector<InteriorEntry> level_below;
  const std::size_t leaf_capacity = LeafCapacity(page_size);
  for (std::size_t begin = 0; begin < sorted_entries.size(); begin += leaf_capacity) {
    std::size_t count = std::min(leaf_capacity, sorted_entries.size() - begin);
    auto entries = sorted_entries.subspan(begin, count);
    sink(next_page, EncodeLeafPage(next_page, entries, page_size));
    level_below.push_back({entries.front().key, next_page});
    ++next_page;
  }
  layout.leaf_page_count = level_below.size();
  layout.height = 1;

  const std::size_t interior_capacity = InteriorCapacity(page_size);
  while (level_below.size() > 1) {
    std::vector<InteriorEntry> level;
    const auto level_number = static_cast<std::uint8_t>(layout.height);
    for (std::size_t begin = 0; begin < level_below.size(); begin += interior_capacity) {
      std::size_t count = std::min(interior_capacity, level_below.size() - begin);
      auto entries = std::span<const InteriorEntry>(level_below).subspan(begin, count);
      sink(next_page, EncodeInteriorPage(next_page, level_number, entries, page_size));
      level.push_back({entries.front().first_key, next_page});
      ++next_page;
    }
    level_below = std::move(level);
    ++layout.height;
  }
  layout.root_page = next_page - 1;
  layout.page_count = next_page - first_page;
  return layout;
}

}  // namespace octocosm
