#include "index/id_index.h"

#include <algorithm>
#include <cstring>

#include "base/error.h"
#include "storage/coding.h"

namespace octocosm {
namespace {

constexpr std::uint32_t kBucketMagic = 0x4249434F;     // "OCIB"
constexpr std::uint32_t kDirectoryMagic = 0x4449434F;  // "OCID"
constexpr std::uint32_t kLeafTableMagic = 0x4C49434F;  // "OCIL"
constexpr std::uint32_t kVersion = 1;                  // of the directory and the leaf table
constexpr std::uint32_t kPairsVersion = 1;             // bucket forms
constexpr std::uint32_t kTableVersion = 2;             // 32-bit ordinals
constexpr std::uint32_t kNarrowTableVersion = 3;       // 16-bit ordinals
constexpr std::uint64_t kMostNarrowOrdinal = 0xFFFF;
constexpr std::size_t kTableHeader = 24;

// Appends a little-endian integer of T's width.
template <typename T>
void Append(Bytes& out, T value) {
  const std::size_t at = out.size();
  out.resize(at + sizeof(T));
  if constexpr (sizeof(T) == 4) PutU32(out.data() + at, value); else PutU64(out.data() + at, value);
}
std::uint64_t GetU64(const Bytes& in, std::size_t offset) { return octocosm::GetU64(in.data() + offset); }
std::uint32_t GetU32(const Bytes& in, std::size_t offset) { return octocosm::GetU32(in.data() + offset); }
std::uint16_t GetU16(const Bytes& in, std::size_t offset) { return octocosm::GetU16(in.data() + offset); }

void CheckLeafKeys(std::span<const std::uint64_t> leaves) {
  for (const std::uint64_t leaf : leaves) {
    if (!NodeKey::FromValue(leaf).IsValid()) {
      throw Error::InvalidArgument("IdIndexEpochWriter: invalid leaf key " + std::to_string(leaf));
    }
  }
}

}  // namespace

IdIndexEpochWriter::IdIndexEpochWriter(StoreWriter& store, std::uint32_t page_size, std::uint64_t first_bucket)
    : store_(store),
      page_size_(page_size),
      first_bucket_(first_bucket),
      bucket_pairs_(BucketPairs(page_size)),
      bucket_(16 + 16 * bucket_pairs_) {}

std::size_t IdIndexEpochWriter::BucketPairs(std::uint32_t page_size) {
  return std::max<std::size_t>((page_size - 16) / 16, 1);
}

std::size_t IdIndexEpochWriter::TableBucketSlots(std::uint32_t page_size, std::uint64_t leaf_count) {
  const std::size_t slot_bytes = leaf_count <= kMostNarrowOrdinal ? 2 : 4;
  return std::max<std::size_t>((page_size - kTableHeader) / slot_bytes, 1);
}

void IdIndexEpochWriter::Add(std::uint64_t id, NodeKey leaf) {
  if (finished_) throw Error::InvalidArgument("IdIndexEpochWriter: Add after Finish");
  if (has_table_) throw Error::InvalidArgument("IdIndexEpochWriter: Add after AddTable");
  if (total_ > 0 && id < last_id_) throw Error::InvalidArgument("IdIndexEpochWriter: IDs must arrive in order");
  if (bucket_fill_ == 0) first_ids_.push_back(id);
  // Straight into the block: a pair costs two stores, no vector growth.
  std::uint8_t* pair = bucket_.data() + 16 + 16 * bucket_fill_;
  PutU64(pair, id);
  PutU64(pair + 8, leaf.value());
  last_id_ = id;
  ++total_;
  if (++bucket_fill_ == bucket_pairs_) FlushBucket();
}

void IdIndexEpochWriter::FlushBucket() {
  if (bucket_fill_ == 0) return;
  PutU32(bucket_.data(), kBucketMagic);
  PutU32(bucket_.data() + 4, kPairsVersion);
  PutU64(bucket_.data() + 8, bucket_fill_);
  store_.AddBlock(first_bucket_ + first_ids_.size() - 1,
                  std::span<const std::uint8_t>(bucket_.data(), 16 + 16 * bucket_fill_), bucket_fill_);
  bucket_fill_ = 0;
}

void IdIndexEpochWriter::AddTable(std::uint64_t first_id, std::span<const std::uint32_t> slots,
                                  std::span<const std::uint64_t> leaves) {
  CheckLeafKeys(leaves);
  AddTableOf(first_id, slots, leaves.size());
  WriteLeafTable(store_, leaves);
}

void IdIndexEpochWriter::AddTable(std::uint64_t first_id, std::span<const std::uint16_t> slots,
                                  std::span<const std::uint64_t> leaves) {
  CheckLeafKeys(leaves);
  AddTableOf(first_id, slots, leaves.size());
  WriteLeafTable(store_, leaves);
}

void IdIndexEpochWriter::AddTableBuckets(std::uint64_t first_id, std::span<const std::uint32_t> slots,
                                         std::uint64_t leaf_count) {
  AddTableOf(first_id, slots, leaf_count);
}

void IdIndexEpochWriter::AddTableBuckets(std::uint64_t first_id, std::span<const std::uint16_t> slots,
                                         std::uint64_t leaf_count) {
  AddTableOf(first_id, slots, leaf_count);
}

template <typename Slot>
void IdIndexEpochWriter::AddTableOf(std::uint64_t first_id, std::span<const Slot> slots, std::uint64_t leaf_count) {
  if (finished_) throw Error::InvalidArgument("IdIndexEpochWriter: AddTable after Finish");
  if (has_table_ || total_ > 0) throw Error::InvalidArgument("IdIndexEpochWriter: AddTable after Add or AddTable");
  if (!slots.empty() && slots.size() - 1 > ~std::uint64_t{0} - first_id) {
    throw Error::InvalidArgument("IdIndexEpochWriter: a table of " + std::to_string(slots.size()) +
                                 " IDs from " + std::to_string(first_id) + " runs past 2^64 - 1");
  }
  has_table_ = true;
  const bool narrow = leaf_count <= kMostNarrowOrdinal;
  const std::size_t slot_bytes = narrow ? 2 : 4;
  const std::size_t per_bucket = TableBucketSlots(page_size_, leaf_count);
  Bytes block(kTableHeader + slot_bytes * std::min(per_bucket, slots.size()));
  for (std::size_t begin = 0; begin < slots.size(); begin += per_bucket) {
    const std::size_t m = std::min(per_bucket, slots.size() - begin);
    const Slot* slot = slots.data() + begin;
    std::uint64_t present = 0;
    std::uint32_t most = 0;
    for (std::size_t i = 0; i < m; ++i) {
      present += slot[i] != 0;
      most = std::max<std::uint32_t>(most, slot[i]);
    }
    if (most > leaf_count) {
      throw Error::InvalidArgument("IdIndexEpochWriter: ordinal " + std::to_string(most) + " for ID " +
                                   std::to_string(first_id + begin) + ".. lies past the " +
                                   std::to_string(leaf_count) + " leaves");
    }
    if (present == 0) continue;  // a look-up lands on the bucket before, whose slots end short of it
    PutU32(block.data(), kBucketMagic);
    PutU32(block.data() + 4, narrow ? kNarrowTableVersion : kTableVersion);
    PutU64(block.data() + 8, first_id + begin);
    PutU64(block.data() + 16, m);
    std::uint8_t* out = block.data() + kTableHeader;
    if (narrow) {
      if constexpr (kHostIsLittleEndian && sizeof(Slot) == 2) {
        std::memcpy(out, slot, 2 * m);
      } else {
        for (std::size_t i = 0; i < m; ++i) PutU16(out + 2 * i, static_cast<std::uint16_t>(slot[i]));
      }
    } else if constexpr (kHostIsLittleEndian && sizeof(Slot) == 4) {
      std::memcpy(out, slot, 4 * m);
    } else {
      for (std::size_t i = 0; i < m; ++i) PutU32(out + 4 * i, slot[i]);
    }
    store_.AddBlock(first_bucket_ + first_ids_.size(),
                    std::span<const std::uint8_t>(block.data(), kTableHeader + slot_bytes * m), present);
    first_ids_.push_back(first_id + begin);
    total_ += present;
  }
}

void IdIndexEpochWriter::WriteLeafTable(StoreWriter& store, std::span<const std::uint64_t> leaves) {
  CheckLeafKeys(leaves);
  Bytes table;
  Append<std::uint32_t>(table, kLeafTableMagic);
  Append<std::uint32_t>(table, kVersion);
  Append<std::uint64_t>(table, leaves.size());
  for (const std::uint64_t leaf : leaves) Append<std::uint64_t>(table, leaf);
  store.AddBlock(kIdIndexLeafTableKey, table, 0);
}

void IdIndexEpochWriter::FinishBuckets() {
  if (finished_) return;
  FlushBucket();
  finished_ = true;
}

void IdIndexEpochWriter::Finish() {
  if (finished_) return;
  FinishBuckets();
  WriteDirectory(store_, first_ids_, total_);
}

void IdIndexEpochWriter::WriteDirectory(StoreWriter& store, std::span<const std::uint64_t> first_ids,
                                        std::uint64_t total) {
  Bytes block;
  Append<std::uint32_t>(block, kDirectoryMagic);
  Append<std::uint32_t>(block, kVersion);
  Append<std::uint64_t>(block, first_ids.size());
  Append<std::uint64_t>(block, total);
  for (std::uint64_t v : first_ids) Append<std::uint64_t>(block, v);
  store.AddBlock(kIdIndexDirectoryKey, block, total);
}

IdIndexReader::IdIndexReader(const std::string& directory) : store_(StoreReader::Open(directory)) {}

// Directories and leaf tables are read outside the lock, so that look-ups in
// several epochs of a store on a server wait for their round trips together;
// two threads that read the same one keep the first.
IdIndexReader::Directory& IdIndexReader::DirectoryOf(std::uint32_t epoch) const {
  {
    MutexLock lock(mutex_);
    if (auto it = directories_.find(epoch); it != directories_.end()) return *it->second;
  }
  const std::string where = store_.directory() + " epoch " + std::to_string(epoch) + " ID directory";
  const Bytes block = store_.ReadBlock({epoch, kIdIndexDirectoryKey});
  if (block.size() < 24 || GetU32(block, 0) != kDirectoryMagic) throw Error::Corruption(where, "wrong magic or short block");
  if (GetU32(block, 4) != kVersion) throw Error::NotSupported(where, "version " + std::to_string(GetU32(block, 4)));
  auto directory = std::make_unique<Directory>();
  const std::uint64_t buckets = GetU64(block, 8);
  directory->total = GetU64(block, 16);
  if (buckets > (block.size() - 24) / 8 || block.size() != 24 + 8 * buckets) {
    throw Error::Corruption(where, "bucket count " + std::to_string(buckets) + " disagrees with the block size");
  }
  directory->first_ids.resize(buckets);
  for (std::uint64_t b = 0; b < buckets; ++b) directory->first_ids[b] = GetU64(block, 24 + 8 * b);
  if (!std::is_sorted(directory->first_ids.begin(), directory->first_ids.end())) {
    throw Error::Corruption(where, "bucket first IDs are not sorted");
  }
  MutexLock lock(mutex_);
  return *directories_.try_emplace(epoch, std::move(directory)).first->second;
}

std::optional<NodeKey> IdIndexReader::Find(std::uint32_t epoch, std::uint64_t id) const {
  return FindAll(epoch, std::span<const std::uint64_t>(&id, 1))[0];
}

std::vector<std::optional<NodeKey>> IdIndexReader::FindAll(std::uint32_t epoch, std::span<const std::uint64_t> ids) const {
  if (epoch >= store_.epoch_count()) {
    throw Error::InvalidArgument("epoch " + std::to_string(epoch) + " (the ID index has " +
                                 std::to_string(store_.epoch_count()) + ")");
  }
  const Directory& directory = DirectoryOf(epoch);
  // (bucket, position in `ids`) for each ID some bucket can hold. Duplicates
  // may span buckets: an ID's bucket is the first that can hold it.
  std::vector<std::pair<std::uint64_t, std::size_t>> wanted;
  wanted.reserve(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    auto it = std::lower_bound(directory.first_ids.begin(), directory.first_ids.end(), ids[i]);
    if (it == directory.first_ids.end() || *it > ids[i]) {
      if (it == directory.first_ids.begin()) continue;
      --it;
    }
    wanted.emplace_back(static_cast<std::uint64_t>(it - directory.first_ids.begin()), i);
  }
  std::sort(wanted.begin(), wanted.end());
  std::vector<std::optional<NodeKey>> found(ids.size());
  for (std::size_t first = 0; first < wanted.size();) {
    const std::uint64_t bucket = wanted[first].first;
    const std::string where = store_.directory() + " epoch " + std::to_string(epoch) + " ID bucket " + std::to_string(bucket);
    const Bytes block = store_.ReadBlock({epoch, bucket});  // once for all the IDs it holds
    if (block.size() < 16 || GetU32(block, 0) != kBucketMagic) throw Error::Corruption(where, "wrong magic or short block");
    const std::uint32_t version = GetU32(block, 4);
    for (; first < wanted.size() && wanted[first].first == bucket; ++first) {
      const std::size_t i = wanted[first].second;
      switch (version) {
        case kPairsVersion:
          found[i] = FindInPairs(block, ids[i], where);
          break;
        case kTableVersion:
          found[i] = FindInTable(epoch, block, ids[i], 4, where);
          break;
        case kNarrowTableVersion:
          found[i] = FindInTable(epoch, block, ids[i], 2, where);
          break;
        default:
          throw Error::NotSupported(where, "version " + std::to_string(version));
      }
    }
  }
  return found;
}

std::optional<NodeKey> IdIndexReader::FindInPairs(const Bytes& block, std::uint64_t id, const std::string& where) const {
  const std::uint64_t n = GetU64(block, 8);
  if (n > (block.size() - 16) / 16 || block.size() != 16 + 16 * n) {
    throw Error::Corruption(where, "pair count " + std::to_string(n) + " disagrees with the block size");
  }
  std::uint64_t lo = 0, hi = n;  // first pair with pair.id >= id
  while (lo < hi) {
    const std::uint64_t mid = lo + (hi - lo) / 2;
    if (GetU64(block, 16 + 16 * mid) < id) lo = mid + 1; else hi = mid;
  }
  if (lo == n || GetU64(block, 16 + 16 * lo) != id) return std::nullopt;
  const NodeKey leaf = NodeKey::FromValue(GetU64(block, 16 + 16 * lo + 8));
  if (!leaf.IsValid()) throw Error::Corruption(where, "invalid node key for ID " + std::to_string(id));
  return leaf;
}

std::optional<NodeKey> IdIndexReader::FindInTable(std::uint32_t epoch, const Bytes& block, std::uint64_t id,
                                                  std::size_t slot_bytes, const std::string& where) const {
  if (block.size() < kTableHeader) throw Error::Corruption(where, "short block");
  const std::uint64_t first = GetU64(block, 8);
  const std::uint64_t m = GetU64(block, 16);
  if (m > (block.size() - kTableHeader) / slot_bytes || block.size() != kTableHeader + slot_bytes * m) {
    throw Error::Corruption(where, "slot count " + std::to_string(m) + " disagrees with the block size");
  }
  if (id < first || id - first >= m) return std::nullopt;
  const std::size_t at = kTableHeader + slot_bytes * (id - first);
  const std::uint32_t ordinal = slot_bytes == 2 ? GetU16(block, at) : GetU32(block, at);
  if (ordinal == 0) return std::nullopt;
  const std::vector<std::uint64_t>& leaves = LeafTableOf(epoch);
  if (ordinal > leaves.size()) {
    throw Error::Corruption(where, "ordinal " + std::to_string(ordinal) + " for ID " + std::to_string(id) +
                                       " lies past the leaf table's " + std::to_string(leaves.size()) + " leaves");
  }
  return NodeKey::FromValue(leaves[ordinal - 1]);  // checked valid when the table was read
}

const std::vector<std::uint64_t>& IdIndexReader::LeafTableOf(std::uint32_t epoch) const {
  Directory& directory = DirectoryOf(epoch);
  {
    MutexLock lock(mutex_);
    if (directory.leaves) return *directory.leaves;
  }
  const std::string where = store_.directory() + " epoch " + std::to_string(epoch) + " ID leaf table";
  if (!store_.Lookup({epoch, kIdIndexLeafTableKey})) throw Error::Corruption(where, "missing, but a bucket needs it");
  const Bytes block = store_.ReadBlock({epoch, kIdIndexLeafTableKey});
  if (block.size() < 16 || GetU32(block, 0) != kLeafTableMagic) throw Error::Corruption(where, "wrong magic or short block");
  if (GetU32(block, 4) != kVersion) throw Error::NotSupported(where, "version " + std::to_string(GetU32(block, 4)));
  const std::uint64_t count = GetU64(block, 8);
  if (count > (block.size() - 16) / 8 || block.size() != 16 + 8 * count) {
    throw Error::Corruption(where, "leaf count " + std::to_string(count) + " disagrees with the block size");
  }
  std::vector<std::uint64_t> keys(count);
  for (std::uint64_t i = 0; i < count; ++i) {
    keys[i] = GetU64(block, 16 + 8 * i);
    if (!NodeKey::FromValue(keys[i]).IsValid()) {
      throw Error::Corruption(where, "invalid node key " + std::to_string(keys[i]) + " at " + std::to_string(i));
    }
  }
  MutexLock lock(mutex_);
  if (!directory.leaves) directory.leaves = std::move(keys);
  return *directory.leaves;
}

}  // namespace octocosm
