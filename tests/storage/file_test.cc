// WritableFile: what is appended, zeros included, is what the file holds.
// Long runs of zeros become holes rather than written bytes; they must still
// read back as zeros, in the middle of the file and at its end, and a
// positioned write into a hole must land.
#include "storage/file.h"

#include <fcntl.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <optional>
#include <thread>
#include <tuple>
#include <vector>

#include "base/error.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

std::vector<std::uint8_t> Bytes(const std::string& text) { return {text.begin(), text.end()}; }

std::vector<std::uint8_t> ReadAll(const std::string& path) { return testing_support::ReadFileBytes(path); }

TEST(WritableFile, ZerosReadBackAsZerosWhetherWrittenOrLeftAsHoles) {
  testing_support::TempDir dir("file-test");
  const std::string path = (dir.path() / "holes").string();
  std::vector<std::uint8_t> expected;
  auto append = [&](WritableFile& file, const std::string& text) {
    file.Append(Bytes(text));
    expected.insert(expected.end(), text.begin(), text.end());
  };
  auto zeros = [&](WritableFile& file, std::size_t count) {
    file.AppendZeros(count);
    expected.insert(expected.end(), count, 0);
  };
  WritableFile file = WritableFile::Create(path);
  zeros(file, 70000);  // a hole at the start, like a page file's header page
  append(file, "first block");
  zeros(file, 100);  // short: written
  append(file, "second");
  zeros(file, 65536 * 3 + 17);  // a hole mid-file
  append(file, "third");
  zeros(file, 200000);  // the file ends in a hole
  EXPECT_EQ(file.size(), expected.size());
  const std::vector<std::uint8_t> header = Bytes("HEADER");
  file.WriteAt(10, header);
  std::copy(header.begin(), header.end(), expected.begin() + 10);
  file.Close();
  EXPECT_EQ(ReadAll(path), expected);
}

TEST(WritableFile, SyncSetsTheLengthOfAFileEndingInAHole) {
  testing_support::TempDir dir("file-test");
  const std::string path = (dir.path() / "trailing").string();
  WritableFile file = WritableFile::Create(path);
  file.Append(Bytes("x"));
  file.AppendZeros(1 << 20);
  file.Sync();
  EXPECT_EQ(ReadAll(path).size(), (1u << 20) + 1);
  file.Append(Bytes("y"));
  file.Close();
  const std::vector<std::uint8_t> bytes = ReadAll(path);
  ASSERT_EQ(bytes.size(), (1u << 20) + 2);
  EXPECT_EQ(bytes.front(), 'x');
  EXPECT_EQ(bytes.back(), 'y');
  EXPECT_EQ(std::count(bytes.begin(), bytes.end(), 0), 1 << 20);
}

// Ranges reserved at the end and filled from several threads at once land
// where they were reserved; what no thread wrote reads as zeros, and appends
// go on after the reserved ranges.
TEST(WritableFile, ReservedRangesFilledFromSeveralThreads) {
  testing_support::TempDir dir("file-test");
  const std::string path = (dir.path() / "reserved").string();
  WritableFile file = WritableFile::Create(path);
  file.Append(Bytes("head"));
  constexpr std::size_t kRanges = 64;
  std::vector<std::uint64_t> offsets;
  std::vector<std::vector<std::uint8_t>> contents;
  std::vector<std::uint8_t> expected = Bytes("head");
  for (std::size_t r = 0; r < kRanges; ++r) {
    const std::size_t length = 5000 + 700 * r;
    offsets.push_back(file.ReserveRange(length));
    // Each range written only in part: the rest stays a hole.
    contents.emplace_back(length - 1000 - r, static_cast<std::uint8_t>(r + 1));
    expected.insert(expected.end(), contents.back().begin(), contents.back().end());
    expected.insert(expected.end(), length - contents.back().size(), 0);
  }
  EXPECT_EQ(file.size(), expected.size());
  std::vector<std::thread> writers;
  for (std::size_t t = 0; t < 4; ++t) {
    writers.emplace_back([&, t] {
      for (std::size_t r = t; r < kRanges; r += 4) file.WriteUnbufferedAt(offsets[r], contents[r]);
    });
  }
  for (std::thread& writer : writers) writer.join();
  file.Append(Bytes("tail"));
  const std::vector<std::uint8_t> tail = Bytes("tail");
  expected.insert(expected.end(), tail.begin(), tail.end());
  file.Close();
  EXPECT_EQ(ReadAll(path), expected);
}

TEST(WriteAllAt, PartsLandOneAfterAnotherBeyondOneCallsWorth) {
  // More parts than one pwritev takes (IOV_MAX, 1024 on Linux), empty ones among them.
  testing_support::TempDir dir("file-test");
  const std::string path = (dir.path() / "parts").string();
  WritableFile::Create(path).Close();
  std::vector<std::vector<std::uint8_t>> parts(2500);
  std::vector<std::uint8_t> expected(100, 0);  // the offset's leading hole
  for (std::size_t p = 0; p < parts.size(); ++p) {
    parts[p].resize(p % 5 == 0 ? 0 : 1 + p % 37);
    for (std::size_t i = 0; i < parts[p].size(); ++i) parts[p][i] = static_cast<std::uint8_t>(p * 3 + i);
    expected.insert(expected.end(), parts[p].begin(), parts[p].end());
  }
  std::vector<std::span<const std::uint8_t>> spans(parts.begin(), parts.end());
  const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  ASSERT_GE(fd, 0);
  EXPECT_EQ(WriteAllAt(fd, 100, spans), 0);
  ::close(fd);
  EXPECT_EQ(ReadAll(path), expected);
}

TEST(CopyFileRange, CopiesARangeIntoTheMiddleOfAnotherFile) {
  testing_support::TempDir dir("file-test");
  const std::string from = (dir.path() / "from").string(), to = (dir.path() / "to").string();
  std::vector<std::uint8_t> source(300000);
  for (std::size_t i = 0; i < source.size(); ++i) source[i] = static_cast<std::uint8_t>(i * 131 + i / 7);
  {
    WritableFile file = WritableFile::Create(from);
    file.Append(source);
    file.Close();
  }
  WritableFile target = WritableFile::Create(to);
  target.Append(Bytes("head"));
  const std::uint64_t at = target.ReserveRange(200000);
  target.Append(Bytes("tail"));
  target.Close();
  CopyFileRange(from, 50000, to, at, 200000);
  std::vector<std::uint8_t> expected = Bytes("head");
  expected.insert(expected.end(), source.begin() + 50000, source.begin() + 250000);
  for (char c : std::string("tail")) expected.push_back(static_cast<std::uint8_t>(c));
  EXPECT_EQ(ReadAll(to), expected);
}

TEST(CopyFileRange, ARangeBeyondTheSourceOrAMissingFileIsAnErrorNamingIt) {
  testing_support::TempDir dir("file-test");
  const std::string from = (dir.path() / "short").string(), to = (dir.path() / "to").string();
  {
    WritableFile file = WritableFile::Create(from);
    file.Append(Bytes("only a few bytes"));
    file.Close();
    WritableFile target = WritableFile::Create(to);
    target.Close();
  }
  auto failure = [](auto&& call) -> std::pair<std::optional<ErrorKind>, std::string> {
    try {
      call();
    } catch (const Error& error) {
      return {error.kind(), error.what()};
    }
    return {std::nullopt, ""};
  };
  auto [kind, message] = failure([&] { CopyFileRange(from, 4, to, 0, 100); });
  EXPECT_EQ(kind, ErrorKind::kCorruption) << message;
  EXPECT_NE(message.find(from), std::string::npos) << message;
  std::tie(kind, message) = failure([&] { CopyFileRange(from, 0, (dir.path() / "absent").string(), 0, 4); });
  EXPECT_EQ(kind, ErrorKind::kIo) << message;
  EXPECT_NE(message.find("absent"), std::string::npos) << message;
}

}  // namespace
}  // namespace octocosm
