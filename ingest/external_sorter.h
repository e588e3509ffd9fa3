// Sorts more records than fit in memory by a 64-bit key: records are
// gathered into runs of at most `run_records`, each run is sorted in memory
// (stably, by radix, so equal keys keep their input order and results are
// reproducible: index/radix_sort.h) and written to a temporary file, and
// reading merges the runs with a heap.
// A set that fits in one run never touches the disk.
//
// Several threads may Add at once. The thread whose records fill a run sorts
// and writes it outside the lock, while the others go on filling the next
// run: memory then holds up to three runs' worth (the run, the sort's
// scratch, the next run), against two for a single adder. Equal keys added
// by different threads come out in the order their records reached the
// sorter.
//
// Record must be trivially copyable and have a member `std::uint64_t key`.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <queue>
#include <span>
#include <string>
#include <type_traits>
#include <vector>

#include "base/error.h"
#include "base/mutex.h"
#include "index/radix_sort.h"
#include "ingest/record_file.h"

namespace octocosm {

template <typename Record>
class ExternalSorter {
  static_assert(std::is_trivially_copyable_v<Record>);

 public:
  // Run files are named `path_prefix` + "-run-N".
  ExternalSorter(std::string path_prefix, std::size_t run_records)
      : prefix_(std::move(path_prefix)), run_records_(std::max<std::size_t>(run_records, 1)) {}
  ExternalSorter(const ExternalSorter&) = delete;
  ExternalSorter& operator=(const ExternalSorter&) = delete;
  ~ExternalSorter() {
    for (const std::string& path : run_paths_) std::remove(path.c_str());
  }

  // Makes room for `records` (at most one run) at once, instead of growing
  // the run buffer step by step, copying it and touching new memory each time.
  void Reserve(std::size_t records) EXCLUDES(mutex_) {
    MutexLock lock(mutex_);
    reserve_ = std::min(records, run_records_);
    buffer_.reserve(reserve_);
  }
  void Add(const Record& record) EXCLUDES(mutex_) { Add(std::span<const Record>(&record, 1)); }
  // May be called from several threads at once (see the top of the file).
  void Add(std::span<const Record> records) EXCLUDES(mutex_) {
    while (!records.empty()) {
      std::vector<Record> full;
      std::string path;
      {
        MutexLock lock(mutex_);
        if (finished_) throw Error::InvalidArgument("ExternalSorter: Add after Finish");
        const std::size_t take = std::min(records.size(), run_records_ - buffer_.size());
        buffer_.insert(buffer_.end(), records.begin(), records.begin() + static_cast<std::ptrdiff_t>(take));
        size_ += take;
        records = records.subspan(take);
        if (buffer_.size() >= run_records_) {
          full.swap(buffer_);
          buffer_.reserve(reserve_);
          path = NextRunPath();
        }
      }
      if (!full.empty()) WriteRun(full, path);
    }
  }

  // Sorts the last run; afterwards only reading is allowed. Every Add must
  // have returned.
  void Finish() EXCLUDES(mutex_) {
    MutexLock lock(mutex_);
    if (finished_) return;
    finished_ = true;
    if (run_paths_.empty()) {
      SortBuffer(buffer_);
      return;
    }
    if (!buffer_.empty()) WriteRun(buffer_, NextRunPath());
    buffer_.clear();
    buffer_.shrink_to_fit();
  }

  // These and Open read unlocked: after Finish no thread adds any more.
  std::uint64_t size() const NO_THREAD_SAFETY_ANALYSIS { return size_; }
  std::size_t run_count() const NO_THREAD_SAFETY_ANALYSIS { return run_paths_.empty() ? (size_ > 0 ? 1 : 0) : run_paths_.size(); }

  // Reads the records in key order. Several readers may be open at once.
  class Reader {
   public:
    bool Next(Record& out) {
      if (memory_ != nullptr) {
        if (memory_index_ >= memory_->size()) return false;
        out = (*memory_)[memory_index_++];
        return true;
      }
      if (active_ == kNoRun) {
        if (heap_.empty()) return false;
        active_ = heap_.top().second;
        heap_.pop();
      }
      RunCursor& run = runs_[active_];
      out = run.current;
      if (!run.file.Next(run.current)) {
        active_ = kNoRun;
      } else if (const HeapItem next{run.current.key, active_}; !heap_.empty() && heap_.top() < next) {
        heap_.push(next);
        active_ = kNoRun;
      }
      return true;
    }

   private:
    friend class ExternalSorter;
    struct RunCursor {
      RecordFileReader<Record> file;
      Record current{};
    };
    using HeapItem = std::pair<std::uint64_t, std::size_t>;  // (key, run); ties by run keep input order
    static constexpr std::size_t kNoRun = SIZE_MAX;
    const std::vector<Record>* memory_ = nullptr;
    std::size_t memory_index_ = 0;
    std::vector<RunCursor> runs_;
    // The run whose record comes next, held out of the heap while it stays
    // ahead of every other: runs filled one after another often cover key
    // ranges that barely overlap (IDs follow space in many snapshots), and
    // then most records cost one comparison instead of a pop and a push.
    std::size_t active_ = kNoRun;
    std::priority_queue<HeapItem, std::vector<HeapItem>, std::greater<>> heap_;
  };

  Reader Open() const NO_THREAD_SAFETY_ANALYSIS {
    if (!finished_) throw Error::InvalidArgument("ExternalSorter: Open before Finish");
    Reader reader;
    if (run_paths_.empty()) {
      reader.memory_ = &buffer_;
      return reader;
    }
    // Read buffers share the run budget: a merge of many runs reads small batches.
    const std::size_t batch = std::max<std::size_t>(run_records_ / run_paths_.size() / 4, 1024);
    reader.runs_.reserve(run_paths_.size());
    for (std::size_t r = 0; r < run_paths_.size(); ++r) {
      auto& cursor = reader.runs_.emplace_back(typename Reader::RunCursor{{run_paths_[r], "a sort run", batch}, {}});
      if (cursor.file.Next(cursor.current)) reader.heap_.push({cursor.current.key, r});
    }
    return reader;
  }

 private:
  // Stable, so equal keys keep their input order (index/radix_sort.h).
  static void SortBuffer(std::vector<Record>& records) {
    if (records.size() < 2) return;
    std::vector<Record> scratch(records.size());
    const std::span<Record> sorted =
        RadixSortByKey(std::span<Record>(records), std::span<Record>(scratch), [](const Record& r) { return r.key; });
    if (sorted.data() != records.data()) records.swap(scratch);
  }

  // The next run's file name, listed at once so that the
  // destructor removes the file even if writing it fails, and so that runs
  // are merged in the order they were filled.
  std::string NextRunPath() REQUIRES(mutex_) {
    run_paths_.push_back(prefix_ + "-run-" + std::to_string(run_paths_.size()));
    return run_paths_.back();
  }

  // Needs no lock: `records` and the file are this caller's alone.
  static void WriteRun(std::vector<Record>& records, const std::string& path) {
    SortBuffer(records);
    RecordFileWriter<Record> file(path, "a sort run");
    file.Write(records);
    file.Close();
  }

  std::string prefix_;
  std::size_t run_records_;
  Mutex mutex_;
  std::size_t reserve_ GUARDED_BY(mutex_) = 0;  // what the next run buffer reserves at once (Reserve)
  std::vector<Record> buffer_ GUARDED_BY(mutex_);
  std::vector<std::string> run_paths_ GUARDED_BY(mutex_);
  std::uint64_t size_ GUARDED_BY(mutex_) = 0;
  bool finished_ GUARDED_BY(mutex_) = false;
};

}  // namespace octocosm
