#include "index/column_reader.h"

#include <algorithm>
#include <string>

#include "storage/error.h"

namespace octocosm {
DecodedBlock ReadBlockColumns(const Dataset& dataset, std::uint32_t epoch, const IndexEntry& entry, ColumnSet wanted,
                              ReadCounters& counters) {
  const PageFileReader& file = dataset.store().page_file(epoch);
  const NodeKey key = NodeKey::FromValue(entry.key);
  const Cube& cube = dataset.cube(epoch);
  const std::string where = dataset.Where(epoch, key);
  ++counters.blocks;
  if ((wanted & kAllColumns) == kAllColumns) {
    // Every column: one read, verified by the page file as well.
    const Bytes block = file.ReadBlock(entry);
    ++counters.reads;
    counters.bytes += block.size();
    return DecodeBlock(block, wanted, key, cube, where);
  }

  // The directory has at most kBlockMaxColumns entries, so this prefix holds
  // the whole header of any block.
  Bytes prefix(static_cast<std::size_t>(std::min<std::uint64_t>(entry.byte_length, kBlockMaxHeaderSize)));
  file.ReadBlockRange(entry, 0, prefix);
  ++counters.reads;
  counters.bytes += prefix.size();
  DecodedBlock decoded;
  decoded.header = DecodeBlockHeader(prefix, key, where);
  const BlockHeader& header = decoded.header;
  if (header.block_size != entry.byte_length) {
    throw Error::Corruption(where, "block header says " + std::to_string(header.block_size) +
                                       " bytes, the index says " + std::to_string(entry.byte_length));
  }
  for (ColumnId required : {ColumnId::kPosition, ColumnId::kWeight, ColumnId::kSmoothing, ColumnId::kType}) {
    if ((wanted & ColumnBit(required)) && header.Find(required) == nullptr) {
      throw Error::Corruption(where, std::string("block lacks the required column '") + ColumnName(required) + "'");
    }
  }
  decoded.points.octant_offsets = header.octant_offsets;

  // Runs of wanted columns that are adjacent in the block, each fetched with
  // one read unless the prefix already holds it.
  const std::vector<BlockColumn>& columns = header.columns;
  std::size_t i = 0;
  Bytes buffer;
  while (i < columns.size()) {
    if (!(wanted & ColumnBit(columns[i].id))) {
      ++i;
      continue;
    }
    std::size_t end = i + 1;
    while (end < columns.size() && (wanted & ColumnBit(columns[end].id)) &&
           columns[end].offset == columns[end - 1].offset + columns[end - 1].length) {
      ++end;
    }
    const std::uint64_t first = columns[i].offset;
    const std::uint64_t last = columns[end - 1].offset + columns[end - 1].length;
    // DecodeBlockHeader checked that every column lies inside block_size.
    std::span<const std::uint8_t> run;
    if (last <= prefix.size()) {
      run = std::span<const std::uint8_t>(prefix).subspan(first, last - first);
    } else {
      buffer.resize(static_cast<std::size_t>(last - first));
      file.ReadBlockRange(entry, first, buffer);
      ++counters.reads;
      counters.bytes += buffer.size();
      run = buffer;
    }
    for (std::size_t c = i; c < end; ++c) {
      DecodeColumn(header, columns[c].id, run.subspan(columns[c].offset - first, columns[c].length), cube, where,
                   decoded.points);
    }
    i = end;
  }
  return decoded;
}

}  // namespace octocosm
