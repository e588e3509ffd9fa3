// DirectWriter: what is queued lands where it was asked to, zero-padded to
// the alignment, from any number of threads, in any order and through a pool
// smaller than the data; a misplaced offset is refused; a failed write is
// reported by the next call rather than lost.
#include "storage/direct_writer.h"

#include <sys/resource.h>
#include <sys/vfs.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <thread>
#include <vector>

#include "base/error.h"
#include "storage/page_file_reader.h"
#include "storage/page_file_writer.h"
#include "tests/storage/storage_test_util.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

using storagetest::ExpectError;
using storagetest::ScratchDirectory;

constexpr std::size_t kAlign = DirectWriter::kAlignment;

// Distinct bytes for write `n`, so a write landing in the wrong place shows.
std::vector<std::uint8_t> Pattern(std::size_t n, std::size_t length) {
  std::vector<std::uint8_t> bytes(length);
  for (std::size_t i = 0; i < length; ++i) bytes[i] = static_cast<std::uint8_t>(1 + (n * 131 + i * 7) % 251);
  return bytes;
}

// Opens a direct writer on a new file in `dir`, or skips the test where the
// temporary directory's file system has no direct I/O (tmpfs).
std::unique_ptr<DirectWriter> OpenOrSkip(const std::string& path, std::size_t in_flight) {
  WritableFile::Create(path).Close();
  return DirectWriter::Open(path, in_flight);
}

TEST(DirectWriter, WritesLandAtTheirOffsetsZeroPaddedFromSeveralThreads) {
  ScratchDirectory dir;
  const std::string path = dir.File("direct");
  // A pool of two alignment units: most writes wait for an earlier one's
  // buffer, and the 3-unit writes are larger than the whole pool.
  auto writer = OpenOrSkip(path, 2 * kAlign);
  if (!writer) GTEST_SKIP() << "no direct I/O on " << dir.path();
  constexpr std::size_t kWrites = 200;
  constexpr std::size_t kSlot = 4 * kAlign;  // each write owns one slot
  std::vector<std::size_t> lengths(kWrites);
  for (std::size_t n = 0; n < kWrites; ++n) lengths[n] = 1 + (n * 4099) % (3 * kAlign);
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < 3; ++t) {
    threads.emplace_back([&, t] {
      for (std::size_t n = t; n < kWrites; n += 3) writer->Write(n * kSlot, Pattern(n, lengths[n]));
    });
  }
  for (std::thread& thread : threads) thread.join();
  writer->Drain();
  writer.reset();

  const std::vector<std::uint8_t> file = testing_support::ReadFileBytes(path);
  const std::size_t last = kWrites - 1;
  ASSERT_EQ(file.size(), last * kSlot + (lengths[last] + kAlign - 1) / kAlign * kAlign);
  for (std::size_t n = 0; n < kWrites; ++n) {
    const std::vector<std::uint8_t> expected = Pattern(n, lengths[n]);
    const std::size_t slot_end = std::min(file.size(), (n + 1) * kSlot);
    ASSERT_TRUE(std::equal(expected.begin(), expected.end(), file.begin() + static_cast<std::ptrdiff_t>(n * kSlot)))
        << "write " << n;
    for (std::size_t i = n * kSlot + lengths[n]; i < slot_end; ++i) ASSERT_EQ(file[i], 0) << "write " << n << " byte " << i;
  }
}

TEST(DirectWriter, WritesThatFollowEachOtherLandWhole) {
  // Writes that continue each other on disk go out several to a call; two
  // threads each write one stream of them, so the queue mixes the streams.
  ScratchDirectory dir;
  const std::string path = dir.File("direct");
  auto writer = OpenOrSkip(path, 64 * kAlign);
  if (!writer) GTEST_SKIP() << "no direct I/O on " << dir.path();
  constexpr std::size_t kWrites = 300;
  constexpr std::size_t kStreamBytes = kWrites * 3 * kAlign;  // the most one stream can take
  std::vector<std::vector<std::uint8_t>> expected(2);
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < 2; ++t) {
    std::vector<std::vector<std::uint8_t>> writes;
    for (std::size_t n = 0; n < kWrites; ++n) {
      writes.push_back(Pattern(t * kWrites + n, (1 + (n + t) % 3) * kAlign));
      expected[t].insert(expected[t].end(), writes.back().begin(), writes.back().end());
    }
    threads.emplace_back([&writer, t, writes = std::move(writes)] {
      std::uint64_t offset = t * kStreamBytes;
      for (const auto& bytes : writes) {
        writer->Write(offset, bytes);
        offset += bytes.size();
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  writer->Drain();
  writer.reset();

  const std::vector<std::uint8_t> file = testing_support::ReadFileBytes(path);
  ASSERT_EQ(file.size(), kStreamBytes + expected[1].size());
  ASSERT_TRUE(std::equal(expected[0].begin(), expected[0].end(), file.begin()));
  for (std::size_t i = expected[0].size(); i < kStreamBytes; ++i) ASSERT_EQ(file[i], 0) << "byte " << i;
  ASSERT_TRUE(std::equal(expected[1].begin(), expected[1].end(), file.begin() + kStreamBytes));
}

TEST(DirectWriter, WritesQueuedOutOfOrderLandWhole) {
  // The writer holds writes back until a batch's worth is queued and then
  // writes them in offset order, joining those that continue each other:
  // pieces queued last first, with a gap every seventh, land as queued.
  ScratchDirectory dir;
  const std::string path = dir.File("direct");
  auto writer = OpenOrSkip(path, 1 << 20);
  if (!writer) GTEST_SKIP() << "no direct I/O on " << dir.path();
  constexpr std::size_t kPieces = 300;
  const auto offset_of = [](std::size_t n) { return (n + n / 7) * kAlign; };
  for (std::size_t n = kPieces; n-- > 0;) writer->Write(offset_of(n), Pattern(n, kAlign - n % 3));
  writer->Drain();
  writer.reset();

  const std::vector<std::uint8_t> file = testing_support::ReadFileBytes(path);
  ASSERT_EQ(file.size(), offset_of(kPieces - 1) + kAlign);
  std::vector<std::uint8_t> expected(file.size(), 0);
  for (std::size_t n = 0; n < kPieces; ++n) {
    const std::vector<std::uint8_t> piece = Pattern(n, kAlign - n % 3);
    std::copy(piece.begin(), piece.end(), expected.begin() + static_cast<std::ptrdiff_t>(offset_of(n)));
  }
  EXPECT_TRUE(file == expected);
}

TEST(DirectWriter, ABatchsWorthGoesOutWithoutDrain) {
  // Writes are held back until a batch's worth is queued; then the writer
  // thread must be woken to write them, with no Drain to ask it.
  ScratchDirectory dir;
  const std::string path = dir.File("direct");
  auto writer = OpenOrSkip(path, 16 << 20);
  if (!writer) GTEST_SKIP() << "no direct I/O on " << dir.path();
  for (std::size_t n = 0; n < DirectWriter::kMaxBatchJobs; ++n) writer->Write(n * kAlign, Pattern(n, kAlign));
  const std::vector<std::uint8_t> first = Pattern(0, kAlign);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::vector<std::uint8_t> file;
  while (std::chrono::steady_clock::now() < deadline) {
    file = testing_support::ReadFileBytes(path);
    if (file.size() >= kAlign && std::equal(first.begin(), first.end(), file.begin())) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_GE(file.size(), kAlign) << "the batch was not written within 20 s";
  EXPECT_TRUE(std::equal(first.begin(), first.end(), file.begin()));
  writer->Drain();
}

TEST(DirectWriter, RefusesAnOffsetOffTheAlignment) {
  ScratchDirectory dir;
  auto writer = OpenOrSkip(dir.File("direct"), 1 << 20);
  if (!writer) GTEST_SKIP() << "no direct I/O on " << dir.path();
  const std::string message = ExpectError(ErrorKind::kInvalidArgument, [&] { writer->Write(100, Pattern(0, 10)); });
  EXPECT_NE(message.find("offset 100"), std::string::npos) << message;
  writer->Write(0, {});  // nothing to write is no error
  writer->Drain();
}

// Runs in a child process: lowers the file-size limit so that a write fails.
[[noreturn]] void FailAWriteAndReport(const std::string& path) {
  std::signal(SIGXFSZ, SIG_IGN);
  auto writer = OpenOrSkip(path, 1 << 20);
  if (!writer) std::_Exit(0);
  rlimit limit{};
  limit.rlim_cur = limit.rlim_max = 64 * kAlign;
  if (::setrlimit(RLIMIT_FSIZE, &limit) != 0) std::_Exit(10);
  writer->Write(0, Pattern(0, kAlign));
  writer->Write(128 * kAlign, Pattern(1, kAlign));  // beyond the limit
  try {
    writer->Drain();
    std::_Exit(11);
  } catch (const Error& error) {
    const std::string what = error.what();
    if (error.kind() != ErrorKind::kIo || what.find(path) == std::string::npos ||
        what.find("offset " + std::to_string(128 * kAlign)) == std::string::npos) {
      std::_Exit(12);
    }
  }
  try {  // and every later call says so too
    writer->Write(2 * kAlign, Pattern(2, 10));
    std::_Exit(13);
  } catch (const Error& error) {
    std::_Exit(error.kind() == ErrorKind::kIo ? 0 : 14);
  }
}

TEST(DirectWriter, AFailedWriteIsReportedByTheNextCall) {
  ScratchDirectory dir;
  EXPECT_EXIT(FailAWriteAndReport(dir.File("limited")), ::testing::ExitedWithCode(0), "");
}

// Linux before 6.6 refuses O_DIRECT on tmpfs (Open returns nullptr and the
// page file goes through the page cache); later kernels take it. Either
// way a page file written to /dev/shm reads back whole.
TEST(DirectWriter, APageFileOnTmpfsReadsBackWhole) {
  constexpr long kTmpfsMagic = 0x01021994;
  struct statfs info {};
  if (::statfs("/dev/shm", &info) != 0 || static_cast<long>(info.f_type) != kTmpfsMagic) {
    GTEST_SKIP() << "no tmpfs at /dev/shm";
  }
  const std::filesystem::path dir = "/dev/shm/octocosm-direct-writer-test-" + std::to_string(::getpid());
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "blocks.pages").string();
  {
    PageFileWriter writer(path, 4096, 7, 0);
    for (std::uint64_t key = 1; key <= 5; ++key) writer.AddBlock(key, Pattern(key, 3000 * key), key);
    writer.Finish();
  }
  auto reader = PageFileReader::Open(path);
  for (std::uint64_t key = 1; key <= 5; ++key) EXPECT_EQ(reader->ReadBlock(key), Pattern(key, 3000 * key)) << key;
  reader.reset();
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace octocosm
