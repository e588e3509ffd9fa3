#include "storage/store_writer.h"

#include <cmath>
#include <random>

#include "storage/error.h"
#include "storage/file.h"

namespace octocosm {
namespace {

std::uint64_t RandomStoreId() {
  std::random_device device;
  std::uint64_t id = 0;
  while (id == 0) id = (std::uint64_t{device()} << 32) ^ device();
  return id;
}

bool IsStoreFileName(const std::string& name) {
  return name.rfind(kManifestFileName, 0) == 0 || name.rfind("epoch-", 0) == 0;
}

}  // namespace

StoreWriter::StoreWriter(std::string directory, nlohmann::json dataset, nlohmann::json attribute_schema,
                         StoreWriterOptions options)
    : directory_(std::move(directory)) {
  if (!IsValidPageSize(options.page_size)) {
    throw Error::InvalidArgument("page size " + std::to_string(options.page_size) +
                                 " is not a power of two in [4096, 16777216]");
  }
  if (!dataset.is_object()) throw Error::InvalidArgument("store dataset metadata must be a JSON object");
  CreateDirectories(directory_);
  // Never write over another store, finished or not: its manifest would
  // otherwise describe files this writer is replacing.
  for (const std::string& name : ListDirectory(directory_)) {
    if (IsStoreFileName(name)) {
      throw Error::InvalidArgument(directory_ + " already holds store file " + name +
                                   "; remove the old store (or its leftovers) first");
    }
  }
  manifest_.store_id = options.store_id != 0 ? options.store_id : RandomStoreId();
  manifest_.page_size = options.page_size;
  manifest_.dataset = std::move(dataset);
  manifest_.attribute_schema = std::move(attribute_schema);
}

StoreWriter::~StoreWriter() {
  if (!finished_) RemoveCreatedFiles();
}

void StoreWriter::RemoveCreatedFiles() noexcept {
  epoch_writer_.reset();  // removes its .tmp file
  for (const std::string& path : created_files_) RemoveFileQuietly(path);
  RemoveFileQuietly(JoinPath(directory_, std::string(kManifestFileName) + kTemporarySuffix));
  created_files_.clear();
}

void StoreWriter::RequireUnfinished(const char* operation) const {
  if (finished_) throw Error::InvalidArgument(std::string(operation) + " after Finish() on store " + directory_);
}

std::uint32_t StoreWriter::BeginEpoch(double time, double redshift) {
  RequireUnfinished("BeginEpoch");
  if (open_epoch_) {
    throw Error::InvalidArgument("BeginEpoch while epoch " + std::to_string(open_epoch_->epoch) + " of " +
                                 directory_ + " is open; call EndEpoch first");
  }
  if (!std::isfinite(time) || !std::isfinite(redshift)) {
    throw Error::InvalidArgument("epoch time and redshift must be finite numbers");
  }
  EpochInfo info;
  info.epoch = static_cast<std::uint32_t>(manifest_.epochs.size());
  info.file = EpochFileName(info.epoch);
  info.time = time;
  info.redshift = redshift;
  epoch_writer_.emplace(JoinPath(directory_, info.file), manifest_.page_size, manifest_.store_id, info.epoch);
  open_epoch_ = info;
  return info.epoch;
}

void StoreWriter::AddBlock(std::uint64_t key, std::span<const std::uint8_t> bytes, std::uint64_t point_count) {
  if (!epoch_writer_) throw Error::InvalidArgument("AddBlock with no open epoch in " + directory_);
  epoch_writer_->AddBlock(key, bytes, point_count);
}

void StoreWriter::EndEpoch() {
  if (!epoch_writer_) throw Error::InvalidArgument("EndEpoch with no open epoch in " + directory_);
  PageFileWriter::Summary summary = epoch_writer_->Finish();
  created_files_.push_back(epoch_writer_->path());
  epoch_writer_.reset();
  EpochInfo info = *open_epoch_;
  open_epoch_.reset();
  info.block_count = summary.block_count;
  info.file_size = summary.file_size;
  finished_bytes_ += summary.file_size;
  manifest_.epochs.push_back(std::move(info));
}

void StoreWriter::SetDataset(nlohmann::json dataset) {
  RequireUnfinished("SetDataset");
  if (!dataset.is_object()) throw Error::InvalidArgument("store dataset metadata must be a JSON object");
  manifest_.dataset = std::move(dataset);
}

void StoreWriter::Finish() {
  RequireUnfinished("Finish");
  if (open_epoch_) {
    throw Error::InvalidArgument("Finish while epoch " + std::to_string(open_epoch_->epoch) + " of " +
                                 directory_ + " is open; call EndEpoch first");
  }
  // The manifest is the commit record: written under a temporary name,
  // made durable, then renamed, so that it exists only complete.
  const std::string final_path = JoinPath(directory_, kManifestFileName);
  const std::string temporary_path = final_path + kTemporarySuffix;
  std::string text = manifest_.ToJson().dump(2) + "\n";
  WritableFile file = WritableFile::Create(temporary_path);
  file.Append(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
  file.Sync();
  file.Close();
  RenameFile(temporary_path, final_path);
  // Until the directory is synced the commit is not durable; if that fails,
  // the destructor removes the manifest with everything else.
  created_files_.push_back(final_path);
  SyncDirectory(directory_);
  finished_bytes_ += text.size();
  finished_ = true;
}

std::uint64_t StoreWriter::bytes_written() const {
  return finished_bytes_ + (epoch_writer_ ? epoch_writer_->bytes_written() : 0);
}

}  // namespace octocosm
