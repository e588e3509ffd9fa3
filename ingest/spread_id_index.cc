#include "ingest/spread_id_index.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <memory>
#include <optional>

#include "base/error.h"
#include "index/id_index.h"
#include "ingest/dense_id_table.h"
#include "ingest/external_sorter.h"

namespace octocosm {

LeafIdsFile::LeafIdsFile(std::string path) : path_(std::move(path)), file_(std::fopen(path_.c_str(), "w+b")) {
  if (file_ == nullptr) throw Error::Io(path_, std::string("cannot create: ") + std::strerror(errno));
}

LeafIdsFile::~LeafIdsFile() {
  if (file_ != nullptr) std::fclose(file_);
  std::remove(path_.c_str());
}

void LeafIdsFile::Add(NodeKey leaf, std::span<const std::uint64_t> ids) {
  const std::uint64_t head[2] = {leaf.value(), ids.size()};
  MutexLock lock(mutex_);
  if (std::fwrite(head, sizeof head, 1, file_) != 1 ||
      (!ids.empty() && std::fwrite(ids.data(), sizeof(std::uint64_t), ids.size(), file_) != ids.size())) {
    throw Error::Io(path_, std::string("cannot write: ") + std::strerror(errno));
  }
  leaves_.push_back(leaf.value());
  for (const std::uint64_t id : ids) {
    if (id_count_++ % sample_stride_ != 0) continue;
    samples_.push_back(id);
    if (samples_.size() == 2 * kSamples) {
      for (std::size_t k = 0; k < kSamples; ++k) samples_[k] = samples_[2 * k];
      samples_.resize(kSamples);
      sample_stride_ *= 2;
    }
  }
}

void LeafIdsFile::Close() {
  MutexLock lock(mutex_);
  std::FILE* file = file_;
  file_ = nullptr;
  if (file != nullptr && std::fclose(file) != 0) {
    throw Error::Io(path_, std::string("cannot write: ") + std::strerror(errno));
  }
}

void LeafIdsFile::ForEach(const std::function<void(NodeKey, std::span<const std::uint64_t>)>& visit) const {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path_.c_str(), "rb"), &std::fclose);
  if (!file) throw Error::Io(path_, std::string("cannot open: ") + std::strerror(errno));
  std::vector<std::uint64_t> ids;
  for (std::uint64_t head[2]; std::fread(head, sizeof head, 1, file.get()) == 1;) {
    if (!NodeKey::FromValue(head[0]).IsValid() || head[1] > (std::uint64_t{1} << 32)) {
      throw Error::Corruption(path_, "not a file of leaves' IDs");
    }
    ids.resize(static_cast<std::size_t>(head[1]));
    if (std::fread(ids.data(), sizeof(std::uint64_t), ids.size(), file.get()) != ids.size()) {
      throw Error::Corruption(path_, "a file of leaves' IDs is cut short");
    }
    visit(NodeKey::FromValue(head[0]), ids);
  }
  if (std::ferror(file.get())) throw Error::Io(path_, std::string("cannot read: ") + std::strerror(errno));
}

namespace {

Bytes Pack(std::span<const std::uint64_t> values) {
  const auto* bytes = reinterpret_cast<const std::uint8_t*>(values.data());
  return Bytes(bytes, bytes + values.size_bytes());
}

template <typename T>
std::vector<T> Unpack(const Bytes& message, const char* what) {
  if (message.size() % sizeof(T) != 0) throw Error::Corruption(what, "a message of " + std::to_string(message.size()) + " bytes");
  std::vector<T> values(message.size() / sizeof(T));
  if (!values.empty()) std::memcpy(values.data(), message.data(), message.size());
  return values;
}

// Every rank's `mine`, one after another in rank order, on every rank.
std::vector<std::uint64_t> AllGather(RankGroup& group, std::span<const std::uint64_t> mine, const char* what) {
  const std::vector<Bytes> incoming = group.Exchange(std::vector<Bytes>(static_cast<std::size_t>(group.size()), Pack(mine)));
  std::vector<std::uint64_t> all;
  for (const Bytes& message : incoming) {
    const std::vector<std::uint64_t> values = Unpack<std::uint64_t>(message, what);
    all.insert(all.end(), values.begin(), values.end());
  }
  return all;
}

// Sends every (ID, leaf) pair of `leaf_ids` to the rank `owner_of` its ID,
// the leaf as `value_of` it, at most `round_pairs` from each rank a round;
// `receive` takes what arrives, by sender. Every rank takes part in every
// round, with nothing to send once its pairs are sent.
void ExchangeToOwners(RankGroup& group, const LeafIdsFile& leaf_ids, std::size_t round_pairs,
                      const std::function<std::uint64_t(NodeKey)>& value_of,
                      const std::function<int(std::uint64_t)>& owner_of,
                      const std::function<void(std::span<const IdLeafRecord>)>& receive) {
  const std::size_t ranks = static_cast<std::size_t>(group.size());
  round_pairs = std::max<std::size_t>(round_pairs, 1);
  std::uint64_t rounds = (leaf_ids.id_count() + round_pairs - 1) / round_pairs;
  group.Max(std::span<std::uint64_t>(&rounds, 1));
  std::vector<std::vector<IdLeafRecord>> outgoing(ranks);
  std::size_t pending = 0;
  std::uint64_t round = 0;
  const auto exchange = [&] {
    std::vector<Bytes> messages(ranks);
    for (std::size_t q = 0; q < ranks; ++q) {
      const auto* bytes = reinterpret_cast<const std::uint8_t*>(outgoing[q].data());
      messages[q].assign(bytes, bytes + outgoing[q].size() * sizeof(IdLeafRecord));
      outgoing[q].clear();
    }
    pending = 0;
    ++round;
    for (const Bytes& message : group.Exchange(messages)) receive(Unpack<IdLeafRecord>(message, leaf_ids.path().c_str()));
  };
  leaf_ids.ForEach([&](NodeKey leaf, std::span<const std::uint64_t> ids) {
    const std::uint64_t value = value_of(leaf);
    for (const std::uint64_t id : ids) {
      outgoing[static_cast<std::size_t>(owner_of(id))].push_back({id, value});
      if (++pending == round_pairs) exchange();
    }
  });
  if (pending > 0) exchange();
  while (round < rounds) exchange();
}

// The smallest ID any rank found given twice, once every rank has looked.
// Rank 0 refuses it (options.refuse_repeated_id), so that the ingest ends
// from rank 0, which removes what the ranks wrote; the others return true
// and write nothing more, and are ended with it.
bool AnyRankFoundARepeat(RankGroup& group, std::optional<std::uint64_t> repeated, const SpreadIdIndexOptions& options,
                         const char* what) {
  std::uint64_t most[2] = {repeated ? 1u : 0u, repeated ? ~*repeated : 0};
  group.Max(most);
  if (most[0] == 0) return false;
  if (group.rank() != 0) return true;
  if (options.refuse_repeated_id) options.refuse_repeated_id(~most[1]);
  throw Error::BadInput(what, "ID " + std::to_string(~most[1]) + " is given to more than one particle");
}

// Rank 0: the directory of every rank's buckets (each rank sends its first
// IDs and its count of IDs), and the leaf table of a table epoch.
void WriteDirectoryOnRankZero(RankGroup& group, const IdIndexEpochWriter& writer, StoreWriter& ids,
                              std::span<const std::uint64_t> leaves, bool table, const char* what) {
  std::vector<std::uint64_t> mine = {writer.total()};
  mine.insert(mine.end(), writer.first_ids().begin(), writer.first_ids().end());
  std::vector<Bytes> outgoing(static_cast<std::size_t>(group.size()));
  outgoing[0] = Pack(mine);
  const std::vector<Bytes> incoming = group.Exchange(outgoing);
  if (group.rank() != 0) return;
  std::vector<std::uint64_t> first_ids;
  std::uint64_t total = 0;
  for (const Bytes& message : incoming) {
    const std::vector<std::uint64_t> values = Unpack<std::uint64_t>(message, what);
    if (values.empty()) throw Error::Corruption(what, "a rank's ID index directory without its count");
    total += values[0];
    first_ids.insert(first_ids.end(), values.begin() + 1, values.end());
  }
  if (!std::is_sorted(first_ids.begin(), first_ids.end())) {
    throw Error::Corruption(what, "the ranks' ID index buckets are out of order");
  }
  IdIndexEpochWriter::WriteDirectory(ids, first_ids, total);
  if (table) IdIndexEpochWriter::WriteLeafTable(ids, leaves);
}

template <typename Slot>
void WriteTableShare(RankGroup& group, const LeafIdsFile& leaf_ids, StoreWriter& ids,
                     const SpreadIdIndexOptions& options, const std::vector<std::uint64_t>& leaves) {
  const char* what = leaf_ids.path().c_str();
  const std::uint64_t ranks = static_cast<std::uint64_t>(group.size());
  const std::uint64_t rank = static_cast<std::uint64_t>(group.rank());
  const std::uint64_t first = options.table_first, span = options.table_span;
  const std::uint64_t per_bucket = IdIndexEpochWriter::TableBucketSlots(options.page_size, leaves.size());
  const std::uint64_t buckets = span == 0 ? 0 : (span - 1) / per_bucket + 1;
  // Rank r owns buckets [lowest[r], lowest[r + 1]) of the whole table.
  std::vector<std::uint64_t> lowest(ranks + 1);
  for (std::uint64_t r = 0; r <= ranks; ++r) {
    lowest[r] = buckets / ranks * r + buckets % ranks * r / ranks;  // buckets * r / ranks, without overflow
  }
  const std::uint64_t begin = lowest[rank] * per_bucket;
  const std::uint64_t end = std::min(lowest[rank + 1] * per_bucket, span);
  std::vector<Slot> slots(end - begin);
  std::optional<std::uint64_t> repeated;
  ExchangeToOwners(
      group, leaf_ids, options.round_pairs,
      [&](NodeKey leaf) -> std::uint64_t {
        const auto at = std::lower_bound(leaves.begin(), leaves.end(), leaf.value());
        return static_cast<std::uint64_t>(at - leaves.begin()) + 1;
      },
      [&](std::uint64_t id) {
        if (id < first || id - first >= span) {
          throw Error::Corruption(what, "ID " + std::to_string(id) + " lies outside the epoch's IDs " +
                                            std::to_string(first) + " .. " + std::to_string(first + span - 1));
        }
        const std::uint64_t bucket = (id - first) / per_bucket;
        return static_cast<int>(std::upper_bound(lowest.begin(), lowest.end() - 1, bucket) - lowest.begin()) - 1;
      },
      [&](std::span<const IdLeafRecord> pairs) {
        for (const IdLeafRecord& pair : pairs) {
          const std::uint64_t slot = pair.key - first - begin;
          if (pair.key < first + begin || slot >= slots.size() || pair.leaf == 0 || pair.leaf > leaves.size()) {
            throw Error::Corruption(what, "ID " + std::to_string(pair.key) + " reached a rank that does not hold it");
          }
          if (slots[slot] != 0) {
            if (!repeated || pair.key < *repeated) repeated = pair.key;
            continue;  // the slot keeps the leaf it had
          }
          slots[slot] = static_cast<Slot>(pair.leaf);
        }
      });
  if (AnyRankFoundARepeat(group, repeated, options, what)) return;
  // Buckets without an ID are left out, so a rank's keys follow the count
  // of buckets the ranks before it write.
  std::uint64_t written = 0;
  for (std::uint64_t b = 0; b < slots.size(); b += per_bucket) {
    const auto bucket_begin = slots.begin() + static_cast<std::ptrdiff_t>(b);
    const auto bucket_end = slots.begin() + static_cast<std::ptrdiff_t>(std::min<std::uint64_t>(b + per_bucket, slots.size()));
    written += std::any_of(bucket_begin, bucket_end, [](Slot s) { return s != 0; });
  }
  const std::vector<std::uint64_t> counts = AllGather(group, std::span<const std::uint64_t>(&written, 1), what);
  std::uint64_t first_bucket = 0;
  for (std::uint64_t r = 0; r < rank; ++r) first_bucket += counts[r];
  IdIndexEpochWriter writer(ids, options.page_size, first_bucket);
  writer.AddTableBuckets(first + begin, std::span<const Slot>(slots), leaves.size());
  writer.FinishBuckets();
  WriteDirectoryOnRankZero(group, writer, ids, leaves, /*table=*/true, what);
}

void WritePairsShare(RankGroup& group, const LeafIdsFile& leaf_ids, StoreWriter& ids,
                     const SpreadIdIndexOptions& options) {
  const char* what = leaf_ids.path().c_str();
  const std::size_t ranks = static_cast<std::size_t>(group.size());
  const int rank = group.rank();
  // The ranks' runs of IDs, cut at quantiles of samples from every rank.
  std::vector<std::uint64_t> all = AllGather(group, leaf_ids.samples(), what);
  std::sort(all.begin(), all.end());
  std::vector<std::uint64_t> cuts;  // rank r owns IDs in [cuts[r - 1], cuts[r])
  for (std::size_t r = 1; r < ranks && !all.empty(); ++r) cuts.push_back(all[r * all.size() / ranks]);
  const auto owner_of = [&cuts](std::uint64_t id) {
    return static_cast<int>(std::upper_bound(cuts.begin(), cuts.end(), id) - cuts.begin());
  };

  ExternalSorter<IdLeafRecord> sorter(options.temp_prefix,
                                static_cast<std::size_t>(std::max<std::uint64_t>(options.sort_memory / sizeof(IdLeafRecord), 1)));
  ExchangeToOwners(
      group, leaf_ids, options.round_pairs, [](NodeKey leaf) { return leaf.value(); }, owner_of,
      [&](std::span<const IdLeafRecord> pairs) {
        for (const IdLeafRecord& pair : pairs) {
          if (owner_of(pair.key) != rank || !NodeKey::FromValue(pair.leaf).IsValid()) {
            throw Error::Corruption(what, "ID " + std::to_string(pair.key) + " reached a rank that does not hold it");
          }
        }
        sorter.Add(pairs);
      });
  sorter.Finish();

  // Buckets hold `per_bucket` consecutive pairs of the whole sorted epoch;
  // a bucket belongs to the rank that holds its first pair, and the pairs
  // of this rank before its first such pair (its head) to the rank before.
  const std::uint64_t count = sorter.size();
  const std::vector<std::uint64_t> counts = AllGather(group, std::span<const std::uint64_t>(&count, 1), what);
  std::vector<std::uint64_t> offsets(ranks + 1, 0);
  for (std::size_t r = 0; r < ranks; ++r) offsets[r + 1] = offsets[r] + counts[r];
  const std::uint64_t per_bucket = IdIndexEpochWriter::BucketPairs(options.page_size);
  const std::uint64_t offset = offsets[static_cast<std::size_t>(rank)];
  const std::uint64_t into_bucket = offset % per_bucket;
  const std::uint64_t head = into_bucket == 0 ? 0 : std::min(count, per_bucket - into_bucket);
  std::size_t head_owner = 0;
  if (head > 0) {
    const std::uint64_t bucket_start = offset - into_bucket;
    while (head_owner + 1 < ranks && offsets[head_owner + 1] <= bucket_start) ++head_owner;
  }

  auto reader = sorter.Open();
  IdLeafRecord pair{};
  std::uint64_t previous = 0;
  std::uint64_t read = 0;
  std::optional<std::uint64_t> repeated;  // sorted: the first found is the smallest
  const auto next = [&] {
    if (!reader.Next(pair)) throw Error::Corruption(what, "the sorted IDs end short");
    if (read++ > 0 && pair.key == previous && !repeated) repeated = pair.key;
    previous = pair.key;
  };
  std::vector<IdLeafRecord> head_pairs;
  for (std::uint64_t k = 0; k < head; ++k) {
    next();
    head_pairs.push_back(pair);
  }
  std::vector<Bytes> outgoing(ranks);
  const auto* head_bytes = reinterpret_cast<const std::uint8_t*>(head_pairs.data());
  outgoing[head_owner].assign(head_bytes, head_bytes + head_pairs.size() * sizeof(IdLeafRecord));
  const std::vector<Bytes> incoming = group.Exchange(outgoing);

  IdIndexEpochWriter writer(ids, options.page_size, (offset + per_bucket - 1) / per_bucket);
  for (std::uint64_t k = head; k < count; ++k) {
    next();
    writer.Add(pair.key, NodeKey::FromValue(pair.leaf));
  }
  for (std::size_t from = static_cast<std::size_t>(rank) + 1; from < ranks; ++from) {
    for (const IdLeafRecord& tail : Unpack<IdLeafRecord>(incoming[from], what)) {
      if (read++ > 0 && tail.key < previous) throw Error::Corruption(what, "the ranks' sorted IDs are out of order");
      if (read > 1 && tail.key == previous && !repeated) repeated = tail.key;
      previous = tail.key;
      writer.Add(tail.key, NodeKey::FromValue(tail.leaf));
    }
  }
  for (std::size_t from = 0; from <= static_cast<std::size_t>(rank); ++from) {
    if (!incoming[from].empty()) throw Error::Corruption(what, "sorted IDs from a rank before this one");
  }
  writer.FinishBuckets();
  if (AnyRankFoundARepeat(group, repeated, options, what)) return;
  WriteDirectoryOnRankZero(group, writer, ids, {}, /*table=*/false, what);
}

}  // namespace

void WriteSpreadIdIndex(RankGroup& group, const LeafIdsFile& leaf_ids, StoreWriter& ids,
                        const SpreadIdIndexOptions& options) {
  if (!options.table) {
    WritePairsShare(group, leaf_ids, ids, options);
    return;
  }
  // The leaf table: every rank's leaves, in key order (domains never share a leaf).
  std::vector<std::uint64_t> leaves = AllGather(group, leaf_ids.leaves(), leaf_ids.path().c_str());
  std::sort(leaves.begin(), leaves.end());
  if (leaves.size() <= DenseIdTable::kMostNarrowLeaves) {
    WriteTableShare<std::uint16_t>(group, leaf_ids, ids, options, leaves);
  } else {
    WriteTableShare<std::uint32_t>(group, leaf_ids, ids, options, leaves);
  }
}

}  // namespace octocosm
