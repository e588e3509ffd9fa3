#include "storage/store_reader.h"

#include <algorithm>
#include <exception>
#include <future>


#include "base/error.h"
#include "storage/checksum.h"
#include "storage/file.h"
#include "storage/http_file.h"

namespace octocosm {
namespace {

bool EndsWith(const std::string& text, const std::string& suffix) {
  return text.size() >= suffix.size() && text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// The directory-level checks of docs/FORMAT.md 1.2 (step 1): an interrupted
// write must never open, and must say so rather than "file not found".
void CheckStoreDirectory(const std::string& directory) {
  if (!IsDirectory(directory)) {
    throw Error::NotFound(directory + ": no such store directory");
  }
  std::vector<std::string> names = ListDirectory(directory);
  bool has_manifest = false;
  bool has_page_files = false;
  for (const std::string& name : names) {
    if (EndsWith(name, kTemporarySuffix)) {
      throw Error::Corruption(JoinPath(directory, name),
                              "leftover temporary file: a write of this store was interrupted; "
                              "the store is not valid (re-create it)");
    }
    if (name == kManifestFileName) has_manifest = true;
    if (EndsWith(name, ".pages")) has_page_files = true;
  }
  if (!has_manifest) {
    if (has_page_files) {
      throw Error::Corruption(directory, "no manifest.json: the store was not finished (interrupted write?)");
    }
    throw Error::NotFound(directory + ": no manifest.json: not an octocosm store");
  }
}

// Page files opened at once for a store on an HTTP server.
constexpr std::size_t kRemoteOpensInFlight = 16;

std::string ReadWholeFile(const std::string& path) {
  std::unique_ptr<ReadableFile> file = OpenReadableFile(path);
  std::string text(static_cast<std::size_t>(file->Size()), '\0');
  std::size_t got = file->ReadAt(0, std::span<std::uint8_t>(reinterpret_cast<std::uint8_t*>(text.data()), text.size()));
  text.resize(got);
  return text;
}

// A store on an HTTP server cannot be listed: its manifest is what makes it a
// store (written last, so an unfinished store has none).
std::string ReadRemoteManifest(const std::string& manifest_url, const std::string& store_url) {
  try {
    return ReadWholeFile(manifest_url);
  } catch (const Error& e) {
    if (e.kind() != ErrorKind::kNotFound) throw;
    throw Error::NotFound(store_url + ": the server has no " + kManifestFileName +
                          " there: not an octocosm store, or not served at that URL");
  }
}

void CheckAgainstManifest(const PageFileReader& file, const EpochInfo& info, const Manifest& manifest,
                          const std::string& manifest_path) {
  const PageFileHeader& header = file.header();
  auto disagree = [&](const std::string& field, const std::string& manifest_value, const std::string& file_value) {
    return Error::Corruption(file.path(), "manifest disagrees with page file: " + manifest_path + " says epoch " +
                                              std::to_string(info.epoch) + " has " + field + " " + manifest_value +
                                              ", the page file has " + file_value);
  };
  if (header.store_id != manifest.store_id) {
    throw disagree("store id", Hex64(manifest.store_id), Hex64(header.store_id) + " (a file from another store?)");
  }
  if (header.epoch != info.epoch) {
    throw disagree("epoch number", std::to_string(info.epoch), std::to_string(header.epoch));
  }
  if (header.page_size != manifest.page_size) {
    throw disagree("page size", std::to_string(manifest.page_size), std::to_string(header.page_size));
  }
  if (header.block_count != info.block_count) {
    throw disagree("block count", std::to_string(info.block_count), std::to_string(header.block_count));
  }
  if (header.file_size() != info.file_size) {
    throw disagree("file size", std::to_string(info.file_size), std::to_string(header.file_size()));
  }
}

// Opens one epoch's page file and checks it against the manifest.
std::unique_ptr<PageFileReader> OpenPageFile(const std::string& directory, const EpochInfo& info,
                                           const Manifest& manifest, const std::string& manifest_path, bool remote,
                                           const StoreReaderOptions& options) {
  const std::string path = JoinPath(directory, info.file);
  const auto missing = [&] {
    return Error::Corruption(path, "missing page file: " + manifest_path + " lists it for epoch " +
                                       std::to_string(info.epoch));
  };
  if (!remote && !PathExists(path)) throw missing();
  // The page file checks its own size against its header; the manifest's
  // file_size is then checked against the header, so any truncation or
  // growth is reported with the file it concerns.
  std::unique_ptr<PageFileReader> reader;
  try {
    reader = PageFileReader::Open(path, PageFileReader::Options{options.index_cache_pages_per_epoch});
  } catch (const Error& e) {
    if (remote && e.kind() == ErrorKind::kNotFound) throw missing();
    throw;
  }
  CheckAgainstManifest(*reader, info, manifest, manifest_path);
  return reader;
}

}  // namespace

StoreReader StoreReader::Open(const std::string& directory, StoreReaderOptions options) {
  const bool remote = IsHttpUrl(directory);
  if (!remote) CheckStoreDirectory(directory);
  const std::string manifest_path = JoinPath(directory, kManifestFileName);
  std::string text = remote ? ReadRemoteManifest(manifest_path, directory) : ReadWholeFile(manifest_path);
  Manifest manifest = Manifest::Parse(text, manifest_path);
  nlohmann::json manifest_json = nlohmann::json::parse(text);  // valid: Parse succeeded

  // Over a network each open costs a round trip: open the epochs' files
  // side by side there.
  const std::size_t parallel = remote ? kRemoteOpensInFlight : 1;
  std::vector<std::unique_ptr<PageFileReader>> page_files(manifest.epochs.size());
  for (std::size_t first = 0; first < manifest.epochs.size(); first += parallel) {
    const std::size_t end = std::min(manifest.epochs.size(), first + parallel);
    std::vector<std::future<std::unique_ptr<PageFileReader>>> opening;
    for (std::size_t e = first; e < end; ++e) {
      opening.push_back(std::async(parallel > 1 ? std::launch::async : std::launch::deferred,
                                   [&, e] { return OpenPageFile(directory, manifest.epochs[e], manifest,
                                                                manifest_path, remote, options); }));
    }
    // get() on each, so every thread is joined before an error propagates.
    std::exception_ptr failure;
    for (std::size_t e = first; e < end; ++e) {
      try {
        page_files[e] = opening[e - first].get();
      } catch (...) {
        if (!failure) failure = std::current_exception();
      }
    }
    if (failure) std::rethrow_exception(failure);
  }
  return StoreReader(directory, std::move(manifest_json), std::move(manifest), std::move(page_files));
}


StoreReader::StoreReader(std::string directory, nlohmann::json manifest_json, Manifest manifest,
                         std::vector<std::unique_ptr<PageFileReader>> page_files)
    : directory_(std::move(directory)),
      manifest_json_(std::move(manifest_json)),
      manifest_(std::move(manifest)),
      page_files_(std::move(page_files)) {
  for (const auto& file : page_files_) coalesces_reads_ = coalesces_reads_ || file->remote();
}

const PageFileReader& StoreReader::page_file(std::uint32_t epoch) const {
  if (epoch >= page_files_.size()) {
    throw Error::NotFound("epoch " + std::to_string(epoch) + " in store " + directory_ + ", which has " +
                          std::to_string(page_files_.size()) + " epochs");
  }
  return *page_files_[epoch];
}

std::uint64_t StoreReader::block_count(std::uint32_t epoch) const { return page_file(epoch).block_count(); }

std::optional<IndexEntry> StoreReader::Lookup(const BlockId& id) const { return page_file(id.epoch).Lookup(id.key); }

IndexEntry StoreReader::Find(const PageFileReader& file, const BlockId& id) {
  std::optional<IndexEntry> entry = file.Lookup(id.key);
  if (!entry) {
    throw Error::NotFound("block " + Hex64(id.key) + " (epoch " + std::to_string(id.epoch) + ") in " + file.path());
  }
  return *entry;
}

void StoreReader::Scan(std::uint32_t epoch, std::uint64_t lo, std::uint64_t hi,
                       const std::function<bool(const IndexEntry&)>& visit) const {
  page_file(epoch).Scan(lo, hi, visit);
}

Bytes StoreReader::ReadBlock(const BlockId& id) const { return page_file(id.epoch).ReadBlock(id.key); }

std::size_t StoreReader::ReadBlockInto(const BlockId& id, std::span<std::uint8_t> out) const {
  const PageFileReader& file = page_file(id.epoch);
  const IndexEntry entry = Find(file, id);
  file.ReadBlockInto(entry, out);
  return static_cast<std::size_t>(entry.byte_length);
}

void StoreReader::ReadBlock(const BlockId& id, Bytes& buffer) const {
  const PageFileReader& file = page_file(id.epoch);
  const IndexEntry entry = Find(file, id);
  buffer.resize(static_cast<std::size_t>(entry.byte_length));
  file.ReadBlockInto(entry, buffer);
}

std::optional<BlockExtent> StoreReader::Locate(const BlockId& id) const {
  if (id.epoch >= page_files_.size()) return std::nullopt;
  const PageFileReader& file = *page_files_[id.epoch];
  const std::optional<IndexEntry> entry = file.Lookup(id.key);
  if (!entry) return std::nullopt;
  return BlockExtent{file.BlockOffset(*entry), entry->byte_length};
}

void StoreReader::ReadBlocks(std::span<const BlockId> ids, std::span<Bytes> buffers) const {
  if (ids.size() != buffers.size()) throw Error::InvalidArgument("ReadBlocks: as many buffers as blocks, please");
  struct Wanted {
    IndexEntry entry;
    std::size_t position;  // in ids
  };
  std::vector<std::size_t> order(ids.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return ids[a].epoch < ids[b].epoch; });
  for (std::size_t begin = 0; begin < order.size();) {
    const std::uint32_t epoch = ids[order[begin]].epoch;
    const PageFileReader& file = page_file(epoch);
    std::vector<Wanted> wanted;
    std::size_t end = begin;
    for (; end < order.size() && ids[order[end]].epoch == epoch; ++end) {
      const BlockId& id = ids[order[end]];
      const IndexEntry entry = Find(file, id);
      wanted.push_back(Wanted{entry, order[end]});
    }
    std::sort(wanted.begin(), wanted.end(),
              [](const Wanted& a, const Wanted& b) { return a.entry.first_page < b.entry.first_page; });
    std::vector<IndexEntry> entries;
    std::vector<std::span<std::uint8_t>> outs;
    for (const Wanted& w : wanted) {
      Bytes& buffer = buffers[w.position];
      buffer.resize(static_cast<std::size_t>(w.entry.byte_length));
      entries.push_back(w.entry);
      outs.emplace_back(buffer);
    }
    file.ReadBlocksInto(entries, outs);
    begin = end;
  }
}

void StoreReader::ReadBlockRange(const BlockId& id, std::uint64_t offset, std::span<std::uint8_t> out) const {
  const PageFileReader& file = page_file(id.epoch);
  const IndexEntry entry = Find(file, id);
  file.ReadBlockRange(entry, offset, out);
}

void StoreReader::DropCaches() const {
  for (const auto& file : page_files_) file->DropCaches();
}

void StoreReader::AdviseSequential() const {
  for (const auto& file : page_files_) file->AdviseSequential();
}

ReaderStats StoreReader::stats() const {
  ReaderStats total;
  for (const auto& file : page_files_) total += file->stats();
  return total;
}

}  // namespace octocosm
