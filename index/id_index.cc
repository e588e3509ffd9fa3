#include "index/id_index.h"

#include <algorithm>
#include <cstring>

#include "storage/coding.h"
#include "storage/error.h"

namespace octocosm {
namespace {

constexpr std::uint32_t kBucketMagic = 0x4249434F;     // "OCIB"
constexpr std::uint32_t kDirectoryMagic = 0x4449434F;  // "OCID"
constexpr std::uint32_t kVersion = 1;

// Appends a little-endian integer of T's width.
template <typename T>
void Append(Bytes& out, T value) {
  const std::size_t at = out.size();
  out.resize(at + sizeof(T));
  if constexpr (sizeof(T) == 4) PutU32(out.data() + at, value); else PutU64(out.data() + at, value);
}
std::uint64_t GetU64(const Bytes& in, std::size_t offset) { return octocosm::GetU64(in.data() + offset); }
std::uint32_t GetU32(const Bytes& in, std::size_t offset) { return octocosm::GetU32(in.data() + offset); }

}  // namespace

IdIndexEpochWriter::IdIndexEpochWriter(StoreWriter& store, std::uint32_t page_size)
    : store_(store),
      bucket_pairs_(std::max<std::size_t>((page_size - 16) / 16, 1)),
      bucket_(16 + 16 * bucket_pairs_) {}

void IdIndexEpochWriter::Add(std::uint64_t id, NodeKey leaf) {
  if (finished_) throw Error::InvalidArgument("IdIndexEpochWriter: Add after Finish");
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
  PutU32(bucket_.data() + 4, kVersion);
  PutU64(bucket_.data() + 8, bucket_fill_);
  store_.AddBlock(first_ids_.size() - 1, std::span<const std::uint8_t>(bucket_.data(), 16 + 16 * bucket_fill_),
                  bucket_fill_);
  bucket_fill_ = 0;
}

void IdIndexEpochWriter::Finish() {
  if (finished_) return;
  FlushBucket();
  Bytes block;
  Append<std::uint32_t>(block, kDirectoryMagic);
  Append<std::uint32_t>(block, kVersion);
  Append<std::uint64_t>(block, first_ids_.size());
  Append<std::uint64_t>(block, total_);
  for (std::uint64_t v : first_ids_) Append<std::uint64_t>(block, v);
  store_.AddBlock(kIdIndexDirectoryKey, block, total_);
  finished_ = true;
}

IdIndexReader::IdIndexReader(const std::string& directory) : store_(StoreReader::Open(directory)) {}

const IdIndexReader::Directory& IdIndexReader::DirectoryOf(std::uint32_t epoch) const {
  std::lock_guard lock(mutex_);
  auto& slot = directories_[epoch];
  if (slot) return *slot;
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
  slot = std::move(directory);
  return *slot;
}

std::optional<NodeKey> IdIndexReader::Find(std::uint32_t epoch, std::uint64_t id) const {
  if (epoch >= store_.epoch_count()) {
    throw Error::InvalidArgument("epoch " + std::to_string(epoch) + " (the ID index has " +
                                 std::to_string(store_.epoch_count()) + ")");
  }
  const Directory& directory = DirectoryOf(epoch);
  // Duplicates may span buckets: start at the first bucket that can hold `id`.
  auto it = std::lower_bound(directory.first_ids.begin(), directory.first_ids.end(), id);
  if (it == directory.first_ids.end() || *it > id) {
    if (it == directory.first_ids.begin()) return std::nullopt;
    --it;
  }
  const auto bucket = static_cast<std::uint64_t>(it - directory.first_ids.begin());
  const std::string where = store_.directory() + " epoch " + std::to_string(epoch) + " ID bucket " + std::to_string(bucket);
  const Bytes block = store_.ReadBlock({epoch, bucket});
  if (block.size() < 16 || GetU32(block, 0) != kBucketMagic) throw Error::Corruption(where, "wrong magic or short block");
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

}  // namespace octocosm
