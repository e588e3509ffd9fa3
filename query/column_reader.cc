#include "query/column_reader.h"

#include <algorithm>
#include <functional>
#include <string>

#include "base/error.h"

namespace octocosm {
namespace {

// Fetches the header and every wanted column of a block with as few reads as
// the layout allows, and hands each wanted column's bytes (unverified) to
// `visit` in directory order. Returns the verified header. Where the caller
// has read the `whole` block already, nothing is read.
BlockHeader FetchColumns(const Dataset& dataset, std::uint32_t epoch, const IndexEntry& entry, ColumnSet wanted,
                         ReadCounters& counters,
                         const std::function<void(const BlockHeader&, std::size_t, std::span<const std::uint8_t>)>& visit,
                         std::span<const std::uint8_t> whole = {}) {
  const PageFileReader& file = dataset.store().page_file(epoch);
  const NodeKey key = NodeKey::FromValue(entry.key);
  const std::string where = dataset.Where(epoch, key);
  ++counters.blocks;

  // The directory has at most kBlockMaxColumns entries, so this prefix holds
  // the whole header of any block. From a server the whole block comes in
  // the same request: a second round trip costs more than the columns skipped.
  Bytes read_prefix;
  std::span<const std::uint8_t> prefix = whole;
  if (prefix.size() != entry.byte_length) {
    const std::uint64_t prefix_bytes = file.remote() ? entry.byte_length : kBlockMaxHeaderSize;
    read_prefix.resize(static_cast<std::size_t>(std::min<std::uint64_t>(entry.byte_length, prefix_bytes)));
    file.ReadBlockRange(entry, 0, read_prefix);
    ++counters.reads;
    counters.bytes += read_prefix.size();
    prefix = read_prefix;
  }
  const BlockHeader header = DecodeBlockHeader(prefix, key, where);
  if (header.block_size != entry.byte_length) {
    throw Error::Corruption(where, "block header says " + std::to_string(header.block_size) +
                                       " bytes, the index says " + std::to_string(entry.byte_length));
  }
  for (ColumnId required : {ColumnId::kPosition, ColumnId::kWeight, ColumnId::kSmoothing, ColumnId::kType}) {
    if ((wanted & ColumnBit(required)) && header.Find(required) == nullptr) {
      throw Error::Corruption(where, std::string("block lacks the required column '") + ColumnName(required) + "'");
    }
  }

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
      run = prefix.subspan(first, last - first);
    } else {
      buffer.resize(static_cast<std::size_t>(last - first));
      file.ReadBlockRange(entry, first, buffer);
      ++counters.reads;
      counters.bytes += buffer.size();
      run = buffer;
    }
    for (std::size_t c = i; c < end; ++c) visit(header, c, run.subspan(columns[c].offset - first, columns[c].length));
    i = end;
  }
  return header;
}

}  // namespace

DecodedBlock ReadBlockColumns(const Dataset& dataset, std::uint32_t epoch, const IndexEntry& entry, ColumnSet wanted,
                              ReadCounters& counters) {
  const NodeKey key = NodeKey::FromValue(entry.key);
  const Cube& cube = dataset.cube(epoch);
  const std::string where = dataset.Where(epoch, key);
  if ((wanted & kAllColumns) == kAllColumns) {
    // Every column: one read, verified by the page file as well.
    ++counters.blocks;
    const Bytes block = dataset.store().page_file(epoch).ReadBlock(entry);
    ++counters.reads;
    counters.bytes += block.size();
    return DecodeBlock(block, wanted, key, cube, where);
  }
  DecodedBlock decoded;
  decoded.header = FetchColumns(
      dataset, epoch, entry, wanted, counters,
      [&](const BlockHeader& header, std::size_t c, std::span<const std::uint8_t> bytes) {
        DecodeColumn(header, header.columns[c].id, bytes, cube, where, decoded.points);
      });
  decoded.points.octant_offsets = decoded.header.octant_offsets;
  return decoded;
}

namespace {

// ReadBlockSubset of the `whole` block where it is given (read already).
Bytes BlockSubset(const Dataset& dataset, std::uint32_t epoch, const IndexEntry& entry, ColumnSet wanted,
                  ReadCounters& counters, std::span<const std::uint8_t> whole) {
  const std::string where = dataset.Where(epoch, NodeKey::FromValue(entry.key));
  // The runs' buffers are reused between reads, so each column is copied out.
  std::vector<Bytes> kept;
  std::vector<std::span<const std::uint8_t>> spans;
  const BlockHeader header = FetchColumns(
      dataset, epoch, entry, wanted, counters,
      [&](const BlockHeader& h, std::size_t c, std::span<const std::uint8_t> bytes) {
        VerifyColumnBytes(h.columns[c], bytes, where);
        if (spans.empty()) {
          kept.resize(h.columns.size());
          spans.resize(h.columns.size());
        }
        kept[c].assign(bytes.begin(), bytes.end());
        spans[c] = kept[c];
      },
      whole);
  spans.resize(header.columns.size());
  return AssembleColumnSubset(header, wanted, spans);
}

}  // namespace

Bytes ReadBlockSubset(const Dataset& dataset, std::uint32_t epoch, const IndexEntry& entry, ColumnSet wanted,
                      ReadCounters& counters) {
  return BlockSubset(dataset, epoch, entry, wanted, counters, {});
}

Bytes ColumnSubsetSource::ReadBlock(const BlockId& id) const {
  const std::optional<IndexEntry> entry = dataset_.store().Lookup(id);
  if (!entry) {
    throw Error::NotFound("block " + NodeKey::FromValue(id.key).Path() + " of epoch " + std::to_string(id.epoch));
  }
  ReadCounters counters;
  Bytes block = ReadBlockSubset(dataset_, id.epoch, *entry, wanted_, counters);
  MutexLock lock(mutex_);
  counters_.blocks += counters.blocks;
  counters_.reads += counters.reads;
  counters_.bytes += counters.bytes;
  return block;
}

bool ColumnSubsetSource::CoalescesReads() const { return dataset_.store().CoalescesReads(); }

std::optional<BlockExtent> ColumnSubsetSource::Locate(const BlockId& id) const { return dataset_.store().Locate(id); }

void ColumnSubsetSource::ReadBlocks(std::span<const BlockId> ids, std::span<Bytes> buffers) const {
  if (ids.size() != buffers.size()) throw Error::InvalidArgument("ReadBlocks: as many buffers as blocks, please");
  // The whole blocks, verified, with as few requests as the store can; the
  // wanted columns are then taken out of each.
  std::vector<Bytes> whole(ids.size());
  dataset_.store().ReadBlocks(ids, whole);
  ReadCounters counters;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const std::optional<IndexEntry> entry = dataset_.store().Lookup(ids[i]);
    if (!entry) {
      throw Error::NotFound("block " + NodeKey::FromValue(ids[i].key).Path() + " of epoch " + std::to_string(ids[i].epoch));
    }
    buffers[i] = BlockSubset(dataset_, ids[i].epoch, *entry, wanted_, counters, whole[i]);
    counters.bytes += whole[i].size();
    // A read per epoch (StoreReader::ReadBlocks).
    if (i == 0 || ids[i].epoch != ids[i - 1].epoch) ++counters.reads;
  }
  MutexLock lock(mutex_);
  counters_.blocks += counters.blocks;
  counters_.reads += counters.reads;
  counters_.bytes += counters.bytes;
}

ReadCounters ColumnSubsetSource::counters() const {
  MutexLock lock(mutex_);
  return counters_;
}

}  // namespace octocosm
