#include "storage/page_file_writer.h"

#include <algorithm>
#include <filesystem>

#include "base/error.h"
#include "storage/block_index_builder.h"
#include "storage/checksum.h"

namespace octocosm {
namespace {

std::string DirectoryOf(const std::string& path) {
  std::string parent = std::filesystem::path(path).parent_path().string();
  return parent.empty() ? "." : parent;
}

// Block bytes copied and waiting for the disk at most: enough to keep the
// disk busy while the builders encode the next blocks.
constexpr std::size_t kDirectBytesInFlight = std::size_t{16} << 20;

// Blocks take the pages from 1 up to the index's first page in every page file.
std::uint64_t BlockPageCount(const PageFileHeader& header) {
  return header.index.first_page > 1 ? header.index.first_page - 1 : 0;
}

}  // namespace

PageFileWriter::PageFileWriter(std::string path, std::uint32_t page_size, std::uint64_t store_id,
                               std::uint32_t epoch)
    : path_(std::move(path)), page_size_(page_size), store_id_(store_id), epoch_(epoch) {
  if (!IsValidPageSize(page_size)) {
    throw Error::InvalidArgument("page size " + std::to_string(page_size) +
                                 " is not a power of two in [4096, 16777216]");
  }
  file_.emplace(WritableFile::Create(temporary_path()));
  // The header page is reserved now and written last, once the index
  // location is known: a file whose header is still zero has no magic and can
  // never be mistaken for a finished one.
  file_->AppendZeros(page_size_);
  direct_ = DirectWriter::Open(temporary_path(), kDirectBytesInFlight);
}

PageFileWriter::~PageFileWriter() {
  direct_.reset();
  if (file_) {
    file_.reset();
    RemoveFileQuietly(temporary_path());
  }
}

void PageFileWriter::RequireOpen(const char* operation) const {
  if (!file_) throw Error::InvalidArgument(std::string(operation) + " on finished page file " + path_);
}

void PageFileWriter::RequireNoFailedWrite(const char* operation) const {
  if (failed_write_) {
    throw Error::Io(temporary_path(), std::string(operation) + " refused: an earlier block write failed");
  }
}

void PageFileWriter::AddBlock(std::uint64_t key, std::span<const std::uint8_t> bytes, std::uint64_t point_count) {
  RequireOpen("AddBlock");
  std::optional<std::uint32_t> pages = PagesForBytes(bytes.size(), page_size_);
  if (!pages) {
    throw Error::InvalidArgument("block " + Hex64(key) + " of " + std::to_string(bytes.size()) +
                                 " bytes needs more than 2^32 pages of " + std::to_string(page_size_));
  }
  IndexEntry entry;
  entry.key = key;
  entry.byte_length = bytes.size();
  entry.point_count = point_count;
  entry.checksum = Checksum64(bytes);
  entry.page_count = *pages;
  std::uint64_t offset = 0;
  {
    MutexLock lock(mutex_);
    RequireNoFailedWrite("AddBlock");
    if (keys_.count(key) != 0) {
      throw Error::InvalidArgument("duplicate key: block " + Hex64(key) + " was already added to epoch " +
                                   std::to_string(epoch_) + " (" + path_ + ")");
    }
    // The padding to whole pages is left a hole: it reads as zeros.
    offset = file_->ReserveRange(std::uint64_t{*pages} * page_size_);
    entry.first_page = bytes.empty() ? 0 : next_page_;
    next_page_ += *pages;
    keys_.insert(key);
    entries_.push_back(entry);
  }
  try {
    // Offsets are whole pages, and pages are whole multiples of direct I/O's
    // alignment, so the zeros it pads a block with stay in the block's pages.
    if (direct_) {
      direct_->Write(offset, bytes);
    } else {
      file_->WriteUnbufferedAt(offset, bytes);
    }
  } catch (...) {
    MutexLock lock(mutex_);
    failed_write_ = true;
    throw;
  }
}

std::uint64_t PageFileWriter::ReserveBlocksOf(const PageFileReader& source) {
  RequireOpen("ReserveBlocksOf");
  if (source.page_size() != page_size_) {
    throw Error::InvalidArgument("blocks of " + source.path() + ", whose pages are " +
                                 std::to_string(source.page_size()) + " bytes, into " + path_ + ", whose pages are " +
                                 std::to_string(page_size_));
  }
  if (source.header().store_id != store_id_ || source.epoch() != epoch_) {
    throw Error::InvalidArgument("blocks of " + source.path() + " (epoch " + std::to_string(source.epoch()) +
                                 " of store " + Hex64(source.header().store_id) + ") into " + path_ + " (epoch " +
                                 std::to_string(epoch_) + " of store " + Hex64(store_id_) + ")");
  }
  std::vector<IndexEntry> added;
  added.reserve(source.block_count());
  source.Scan(0, ~std::uint64_t{0}, [&added](const IndexEntry& entry) {
    added.push_back(entry);
    return true;
  });
  const std::uint64_t pages = BlockPageCount(source.header());
  MutexLock lock(mutex_);
  RequireNoFailedWrite("ReserveBlocksOf");
  for (const IndexEntry& entry : added) {
    if (keys_.count(entry.key) != 0) {
      throw Error::InvalidArgument("duplicate key: block " + Hex64(entry.key) + " of " + source.path() +
                                   " was already added to epoch " + std::to_string(epoch_) + " (" + path_ + ")");
    }
  }
  const std::uint64_t offset = file_->ReserveRange(pages * page_size_);
  const std::uint64_t first_page = next_page_;
  next_page_ += pages;
  for (IndexEntry entry : added) {
    if (entry.first_page != 0) entry.first_page = entry.first_page - 1 + first_page;
    keys_.insert(entry.key);
    entries_.push_back(entry);
  }
  return offset;
}

void CopyBlockPages(const std::string& source, const std::string& target, std::uint64_t offset) {
  const std::unique_ptr<PageFileReader> reader = PageFileReader::Open(source);
  const std::uint64_t page_size = reader->page_size();
  CopyFileRange(source, page_size, target, offset, BlockPageCount(reader->header()) * page_size);
}

PageFileWriter::Summary PageFileWriter::Finish() {
  RequireOpen("Finish");
  RequireNoFailedWrite("Finish");
  if (direct_) {
    try {
      direct_->Drain();
    } catch (...) {
      failed_write_ = true;
      throw;
    }
    direct_.reset();
  }
  std::vector<IndexEntry> sorted = entries_;
  std::sort(sorted.begin(), sorted.end(), [](const IndexEntry& a, const IndexEntry& b) { return a.key < b.key; });

  const std::uint64_t index_first_page = next_page_;
  IndexLayout layout = BuildBlockIndex(sorted, index_first_page, page_size_,
                                       [&](std::uint64_t page_number, std::span<const std::uint8_t> page) {
                                         // Pages are appended in order, so each lands at its number.
                                         if (file_->size() != page_number * page_size_) {
                                           throw Error::InvalidArgument("index page out of place (bug)");
                                         }
                                         file_->Append(page);
                                       });
  PageFileHeader header;
  header.page_size = page_size_;
  header.store_id = store_id_;
  header.epoch = epoch_;
  header.block_count = sorted.size();
  header.total_page_count = index_first_page + layout.page_count;
  header.index = layout;
  auto encoded = header.Encode();
  file_->WriteAt(0, encoded);
  file_->Sync();
  const std::uint64_t size = file_->size();
  file_->Close();
  RenameFile(temporary_path(), path_);
  file_.reset();
  finished_size_ = size;
  SyncDirectory(DirectoryOf(path_));
  return Summary{sorted.size(), size};
}

}  // namespace octocosm
