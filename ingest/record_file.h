// Temporary files of fixed-size records (sort runs, epoch links): written and
// read in large batches, so a record costs a copy and no call of its own.
// They live only for one ingest, in its temporary directory, in the host's
// byte order.
//
// Record must be trivially copyable.
#pragma once

#include <cerrno>
#include <cstdio>
#include <memory>
#include <span>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "base/error.h"

namespace octocosm {

using FileHandle = std::unique_ptr<std::FILE, int (*)(std::FILE*)>;

template <typename Record>
class RecordFileWriter {
  static_assert(std::is_trivially_copyable_v<Record>);

 public:
  // Creates (or truncates) `path`; `what` names the file in errors ("a sort run").
  RecordFileWriter(std::string path, std::string what, std::size_t batch_records = 4096)
      : path_(std::move(path)), what_(std::move(what)), batch_records_(std::max<std::size_t>(batch_records, 1)) {
    file_.reset(std::fopen(path_.c_str(), "wb"));
    if (!file_) throw IoErrorFromErrno(path_, "creating " + what_, errno);
    buffer_.reserve(batch_records_);
  }

  void Add(const Record& record) {
    buffer_.push_back(record);
    if (buffer_.size() >= batch_records_) Flush();
  }
  void Write(std::span<const Record> records) {
    Flush();
    WriteBytes(records.data(), records.size());
  }
  // Writes what is buffered and closes the file; throws Error::Io (disk full).
  void Close() {
    if (!file_) return;
    Flush();
    std::FILE* file = file_.release();
    const bool flushed = std::fflush(file) == 0;
    const int flush_errno = errno;
    const bool closed = std::fclose(file) == 0;
    if (!flushed || !closed) {
      throw IoErrorFromErrno(path_, "writing " + what_ + " (is the temporary directory full?)",
                             flushed ? errno : flush_errno);
    }
  }

 private:
  void Flush() {
    WriteBytes(buffer_.data(), buffer_.size());
    buffer_.clear();
  }
  void WriteBytes(const Record* records, std::size_t count) {
    if (count == 0) return;
    if (std::fwrite(records, sizeof(Record), count, file_.get()) != count) {
      throw IoErrorFromErrno(path_, "writing " + what_ + " (is the temporary directory full?)", errno);
    }
  }

  std::string path_;
  std::string what_;
  std::size_t batch_records_;
  FileHandle file_{nullptr, &std::fclose};
  std::vector<Record> buffer_;
};

template <typename Record>
class RecordFileReader {
  static_assert(std::is_trivially_copyable_v<Record>);

 public:
  RecordFileReader(std::string path, std::string what, std::size_t batch_records = 4096)
      : path_(std::move(path)), what_(std::move(what)), batch_(std::max<std::size_t>(batch_records, 1)) {
    file_.reset(std::fopen(path_.c_str(), "rb"));
    if (!file_) throw IoErrorFromErrno(path_, "opening " + what_, errno);
  }

  // The next record; false at the end of the file.
  bool Next(Record& out) {
    if (index_ == filled_) {
      filled_ = std::fread(batch_.data(), sizeof(Record), batch_.size(), file_.get());
      index_ = 0;
      if (filled_ == 0) {
        if (std::ferror(file_.get())) throw IoErrorFromErrno(path_, "reading " + what_, errno);
        return false;
      }
    }
    out = batch_[index_++];
    return true;
  }

  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::string what_;
  FileHandle file_{nullptr, &std::fclose};
  std::vector<Record> batch_;
  std::size_t index_ = 0, filled_ = 0;
};

}  // namespace octocosm
