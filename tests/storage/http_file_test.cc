// HttpFile against a scripted server: ranges read as from a local file, and
// every fault (missing file, refused access, a server that ignores ranges,
// answers a wrong or short range, changes the file, fails for a while, goes
// silent or is not there) ends as the error that says so, or as a bounded
// retry that succeeds: never wrong bytes, never a hang.
#include "storage/http_file.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <random>
#include <thread>

#include "base/error.h"
#include "storage/range_cache.h"
#include "storage/read_cancellation.h"
#include "tests/support/fake_http_server.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

using testing_support::FakeHttpServer;
using Answer = FakeHttpServer::Answer;

std::string RandomBytes(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::string bytes(n, '\0');
  for (char& c : bytes) c = static_cast<char>(rng());
  return bytes;
}

std::string Read(const ReadableFile& file, std::uint64_t offset, std::size_t length) {
  std::string out(length, '\0');
  const std::size_t got = file.ReadAt(offset, std::span<std::uint8_t>(reinterpret_cast<std::uint8_t*>(out.data()), length));
  out.resize(got);
  return out;
}

// Fast retries and a short stall limit, so fault tests take a second.
HttpOptions QuickOptions() {
  HttpOptions options;
  options.stall_timeout_s = 1;
  options.first_backoff_s = 0.01;
  options.retries = 2;
  return options;
}

template <typename F>
Error ErrorOf(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e;
  }
  ADD_FAILURE() << "no error thrown";
  return Error::InvalidArgument("no error");
}

TEST(HttpFile, ReadsRangesAsALocalFileWould) {
  FakeHttpServer server;
  const std::string contents = RandomBytes(300000, 1);
  server.Put("/store/epoch.pages", contents);
  auto file = HttpFile::Open(server.Url("/store/epoch.pages"), QuickOptions());
  EXPECT_EQ(file->Size(), contents.size());
  EXPECT_EQ(file->path(), server.Url("/store/epoch.pages"));
  EXPECT_EQ(Read(*file, 0, 128), contents.substr(0, 128));                 // from the first request
  EXPECT_EQ(Read(*file, 65530, 100), contents.substr(65530, 100));        // across the first request's end
  EXPECT_EQ(Read(*file, 200000, 50000), contents.substr(200000, 50000));  // a range request
  EXPECT_EQ(Read(*file, 299990, 100), contents.substr(299990));           // cut at the end of the file
  EXPECT_EQ(Read(*file, 300000, 10), "");
  // One request to open, two for the ranges beyond the first bytes, all on
  // one kept-alive connection.
  EXPECT_EQ(file->stats().requests, 4u);
  EXPECT_EQ(server.connections(), 1);
}

TEST(HttpFile, AResidentRangeIsFetchedOnceAndServesItsPieces) {
  FakeHttpServer server;
  const std::string contents = RandomBytes(1 << 20, 10);
  server.Put("/f", contents);
  auto file = HttpFile::Open(server.Url("/f"), QuickOptions());
  file->KeepResident(700000, 200000);
  for (std::uint64_t offset = 700000; offset + 4096 <= 900000; offset += 4096) {
    ASSERT_EQ(Read(*file, offset, 4096), contents.substr(offset, 4096));
  }
  EXPECT_EQ(file->stats().requests, 2u);  // the open and the range
  EXPECT_EQ(Read(*file, 650000, 4096), contents.substr(650000, 4096));  // outside it: a request of its own
  EXPECT_EQ(file->stats().requests, 3u);
}

TEST(HttpFile, ASmallFileComesWholeWithTheFirstRequest) {
  FakeHttpServer server;
  server.Put("/manifest.json", "{\"x\": 1}");
  server.Put("/empty", "");
  auto file = HttpFile::Open(server.Url("/manifest.json"), QuickOptions());
  EXPECT_EQ(file->Size(), 8u);
  EXPECT_EQ(Read(*file, 0, 100), "{\"x\": 1}");
  EXPECT_EQ(file->stats().requests, 1u);
  auto empty = HttpFile::Open(server.Url("/empty"), QuickOptions());
  EXPECT_EQ(empty->Size(), 0u);
  EXPECT_EQ(Read(*empty, 0, 10), "");
}

std::vector<RangeRead> Ranges(std::vector<std::pair<std::uint64_t, std::size_t>> wanted,
                              std::vector<std::string>& buffers) {
  buffers.clear();
  for (const auto& [offset, length] : wanted) buffers.emplace_back(length, '\0');
  std::vector<RangeRead> ranges;
  for (std::size_t i = 0; i < wanted.size(); ++i) {
    ranges.push_back(RangeRead{wanted[i].first,
                               std::span<std::uint8_t>(reinterpret_cast<std::uint8_t*>(buffers[i].data()), buffers[i].size())});
  }
  return ranges;
}

// One answer of several megabytes arrives in many runs, which start and end
// anywhere: inside a range, between two, across several small ones.
TEST(HttpFile, ManyRangesOfOneRequestEachGetTheirBytesAcrossTheAnswersRuns) {
  FakeHttpServer server;
  const std::string contents = RandomBytes(6 << 20, 5);
  server.Put("/f", contents);
  std::mt19937_64 random(11);
  std::vector<std::pair<std::uint64_t, std::size_t>> wanted;
  for (std::uint64_t at = 70000; wanted.size() < 300;) {
    const std::size_t length = 1 + random() % (random() % 4 == 0 ? 200000 : 3000);
    if (at + length > contents.size()) break;
    wanted.emplace_back(at, length);
    at += length + random() % 3 * (random() % 5000);  // a third adjacent, the rest with a gap
  }
  ASSERT_GT(wanted.back().first, std::uint64_t{2} << 20) << "an answer longer than libcurl's receive buffer";
  auto file = HttpFile::Open(server.Url("/f"), QuickOptions());
  std::vector<std::string> buffers;
  std::vector<RangeRead> ranges = Ranges(wanted, buffers);
  file->ReadRanges(ranges);
  for (std::size_t i = 0; i < wanted.size(); ++i) {
    ASSERT_EQ(ranges[i].got, wanted[i].second) << i;
    ASSERT_EQ(buffers[i], contents.substr(wanted[i].first, wanted[i].second)) << "range " << i;
  }
  EXPECT_EQ(file->stats().requests, 2u);  // the open and one for all ranges
}

TEST(HttpFile, SeveralRangesComeWithOneRequestAndAreCachedOneByOne) {
  FakeHttpServer server;
  const std::string contents = RandomBytes(1 << 20, 3);
  server.Put("/f", contents);
  testing_support::TempDir cache_dir("http-ranges");
  HttpOptions options = QuickOptions();
  options.cache = RangeCache::Open(cache_dir.path().string(), 16 << 20);
  const std::vector<std::pair<std::uint64_t, std::size_t>> wanted = {
      {100000, 5000}, {110000, 3000}, {200000, 10000}, {(1 << 20) - 100, 300}};
  {
    auto file = HttpFile::Open(server.Url("/f"), options);
    std::vector<std::string> buffers;
    std::vector<RangeRead> ranges = Ranges(wanted, buffers);
    file->ReadRanges(ranges);
    for (std::size_t i = 0; i < wanted.size(); ++i) {
      const std::size_t expected = i + 1 < wanted.size() ? wanted[i].second : 100;  // the last is cut at the end
      ASSERT_EQ(ranges[i].got, expected) << i;
      EXPECT_EQ(buffers[i].substr(0, expected), contents.substr(wanted[i].first, expected)) << i;
    }
    EXPECT_EQ(file->stats().requests, 2u);  // the open and one for all four ranges
  }
  {
    // Each range was cached on its own: a reader asking for some of them,
    // and one more, fetches only that one.
    auto file = HttpFile::Open(server.Url("/f"), options);
    std::vector<std::string> buffers;
    std::vector<RangeRead> ranges = Ranges({{110000, 3000}, {150000, 64}, {200000, 10000}}, buffers);
    file->ReadRanges(ranges);
    EXPECT_EQ(buffers[0], contents.substr(110000, 3000));
    EXPECT_EQ(buffers[1], contents.substr(150000, 64));
    EXPECT_EQ(buffers[2], contents.substr(200000, 10000));
    EXPECT_EQ(file->stats().requests, 2u);
    EXPECT_EQ(file->stats().bytes_fetched, 65536u + 64u);  // the open's first bytes and the one range
  }
  {
    auto file = HttpFile::Open(server.Url("/f"), QuickOptions());
    std::vector<std::string> buffers;
    std::vector<RangeRead> ranges = Ranges({{200000, 10}, {100000, 10}}, buffers);
    EXPECT_EQ(ErrorOf([&] { file->ReadRanges(ranges); }).kind(), ErrorKind::kInvalidArgument);
    ranges = Ranges({{100000, 10}, {100005, 10}}, buffers);
    EXPECT_EQ(ErrorOf([&] { file->ReadRanges(ranges); }).kind(), ErrorKind::kInvalidArgument);
  }
}

TEST(HttpFile, ManyThreadsReadAtOnce) {
  FakeHttpServer server;
  const std::string contents = RandomBytes(1 << 20, 2);
  server.Put("/f", contents);
  auto file = HttpFile::Open(server.Url("/f"), QuickOptions());
  std::vector<std::thread> threads;
  std::atomic<int> wrong{0};
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&, t] {
      std::mt19937 rng(t);
      for (int i = 0; i < 40; ++i) {
        const std::uint64_t offset = rng() % contents.size();
        const std::size_t length = 1 + rng() % 20000;
        if (Read(*file, offset, length) != contents.substr(offset, length)) ++wrong;
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_LE(server.connections(), 8);  // connections are kept and reused
}

TEST(HttpFile, AMissingFileIsNotFound) {
  FakeHttpServer server;
  const Error e = ErrorOf([&] { HttpFile::Open(server.Url("/nothing"), QuickOptions()); });
  EXPECT_EQ(e.kind(), ErrorKind::kNotFound);
  EXPECT_NE(std::string(e.what()).find(server.Url("/nothing")), std::string::npos) << e.what();
  EXPECT_NE(std::string(e.what()).find("404"), std::string::npos) << e.what();
}

TEST(HttpFile, RefusedAccessIsAnIoErrorAndIsNotRetried) {
  FakeHttpServer server;
  server.Put("/f", "x");
  server.SetScript([](const FakeHttpServer::Request&) { return FakeHttpServer::Behaviour{Answer::kStatus, 403}; });
  const Error e = ErrorOf([&] { HttpFile::Open(server.Url("/f"), QuickOptions()); });
  EXPECT_EQ(e.kind(), ErrorKind::kIo);
  EXPECT_NE(std::string(e.what()).find("refuses access (HTTP 403)"), std::string::npos) << e.what();
  EXPECT_EQ(server.requests(), 1);
}

TEST(HttpFile, AServerThatIgnoresRangesIsRefusedWithoutReadingTheWholeFile) {
  FakeHttpServer server;
  server.Put("/big", RandomBytes(8 << 20, 3));
  server.SetScript([](const FakeHttpServer::Request&) { return FakeHttpServer::Behaviour{Answer::kIgnoreRange}; });
  auto options = QuickOptions();
  const Error e = ErrorOf([&] { HttpFile::Open(server.Url("/big"), options); });
  EXPECT_EQ(e.kind(), ErrorKind::kIo);
  EXPECT_NE(std::string(e.what()).find("ignored the range request"), std::string::npos) << e.what();
}

TEST(HttpFile, AServerThatStopsHonouringRangesIsAnError) {
  FakeHttpServer server;
  server.Put("/big", RandomBytes(1 << 20, 4));
  auto file = HttpFile::Open(server.Url("/big"), QuickOptions());
  server.SetScript([](const FakeHttpServer::Request&) { return FakeHttpServer::Behaviour{Answer::kIgnoreRange}; });
  const Error e = ErrorOf([&] { Read(*file, 500000, 1000); });
  EXPECT_EQ(e.kind(), ErrorKind::kIo);
  EXPECT_NE(std::string(e.what()).find("ignored the range request for bytes 500000-500999"), std::string::npos)
      << e.what();
}

TEST(HttpFile, AWrongRangeIsAnError) {
  FakeHttpServer server;
  server.Put("/f", RandomBytes(1 << 20, 5));
  auto file = HttpFile::Open(server.Url("/f"), QuickOptions());
  server.SetScript([](const FakeHttpServer::Request&) { return FakeHttpServer::Behaviour{Answer::kWrongRange}; });
  const Error e = ErrorOf([&] { Read(*file, 100000, 1000); });
  EXPECT_EQ(e.kind(), ErrorKind::kIo);
  EXPECT_NE(std::string(e.what()).find("answered a request for bytes 100000-100999 with bytes 100001-100999"),
            std::string::npos)
      << e.what();
}

TEST(HttpFile, AFileChangedOnTheServerIsCorruptionNotAMixOfVersions) {
  FakeHttpServer server;
  const std::string contents = RandomBytes(1 << 20, 6);
  server.Put("/f", contents);
  auto file = HttpFile::Open(server.Url("/f"), QuickOptions());
  server.SetScript([](const FakeHttpServer::Request&) { return FakeHttpServer::Behaviour{Answer::kChangedEtag}; });
  Error e = ErrorOf([&] { Read(*file, 100000, 1000); });
  EXPECT_EQ(e.kind(), ErrorKind::kCorruption);
  EXPECT_NE(std::string(e.what()).find("changed on the server since it was opened"), std::string::npos) << e.what();
  // A file that shrank: the range is past its new end.
  server.SetScript(nullptr);
  server.Put("/f", contents.substr(0, 200000));
  e = ErrorOf([&] { Read(*file, 500000, 1000); });
  EXPECT_EQ(e.kind(), ErrorKind::kCorruption);
  EXPECT_NE(std::string(e.what()).find("changed on the server"), std::string::npos) << e.what();
}

TEST(HttpFile, PassingFailuresAreRetriedAndThenSucceed) {
  FakeHttpServer server;
  const std::string contents = RandomBytes(1 << 20, 7);
  server.Put("/f", contents);
  auto file = HttpFile::Open(server.Url("/f"), QuickOptions());
  // The next two requests fail (a 503, then a transfer cut short); the third serves.
  const int first = server.requests();
  server.SetScript([first](const FakeHttpServer::Request& r) {
    if (r.number == first) return FakeHttpServer::Behaviour{Answer::kStatus, 503};
    if (r.number == first + 1) return FakeHttpServer::Behaviour{Answer::kCutShort};
    return FakeHttpServer::Behaviour{};
  });
  EXPECT_EQ(Read(*file, 400000, 70000), contents.substr(400000, 70000));
  EXPECT_EQ(file->stats().retries, 2u);
}

TEST(HttpFile, FailuresThatPersistEndAfterBoundedRetries) {
  FakeHttpServer server;
  server.Put("/f", RandomBytes(1 << 20, 8));
  auto file = HttpFile::Open(server.Url("/f"), QuickOptions());
  server.SetScript([](const FakeHttpServer::Request&) { return FakeHttpServer::Behaviour{Answer::kCutShort}; });
  const Error e = ErrorOf([&] { Read(*file, 400000, 70000); });
  EXPECT_EQ(e.kind(), ErrorKind::kIo);
  EXPECT_NE(std::string(e.what()).find("gave up after 3 attempts"), std::string::npos) << e.what();
  EXPECT_EQ(file->stats().retries, 2u);
}

TEST(HttpFile, ASilentServerTimesOut) {
  FakeHttpServer server;
  server.Put("/f", RandomBytes(1 << 20, 9));
  auto file = HttpFile::Open(server.Url("/f"), QuickOptions());
  server.SetScript([](const FakeHttpServer::Request&) { return FakeHttpServer::Behaviour{Answer::kSilence}; });
  const auto start = std::chrono::steady_clock::now();
  const Error e = ErrorOf([&] { Read(*file, 400000, 70000); });
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(e.kind(), ErrorKind::kIo);
  EXPECT_NE(std::string(e.what()).find("gave up"), std::string::npos) << e.what();
  EXPECT_LT(seconds, 30.0);  // 3 attempts of a 1 s stall limit each, and the backoff
}

// A read whose caller cancels it (a prefetch no longer wanted) stops while
// the server keeps it waiting: at once, not after the stall limit, and with
// no retry. The same file reads on afterwards.
TEST(HttpFile, ACancelledReadStopsItsTransferAndIsNotRetried) {
  FakeHttpServer server;
  const std::string contents = RandomBytes(1 << 20, 10);
  server.Put("/f", contents);
  HttpOptions options;
  options.stall_timeout_s = 20;
  auto file = HttpFile::Open(server.Url("/f"), options);
  server.SetScript([](const FakeHttpServer::Request&) { return FakeHttpServer::Behaviour{Answer::kSilence}; });
  const int requests_before = server.requests();
  std::atomic<bool> cancelled{false};
  std::thread canceller([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    cancelled = true;
  });
  const auto start = std::chrono::steady_clock::now();
  const Error e = ErrorOf([&] {
    const ReadCancellationScope scope(&cancelled);
    Read(*file, 400000, 70000);
  });
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  canceller.join();
  EXPECT_EQ(e.kind(), ErrorKind::kIo);
  EXPECT_NE(std::string(e.what()).find("read cancelled"), std::string::npos) << e.what();
  EXPECT_NE(std::string(e.what()).find(server.Url("/f")), std::string::npos) << e.what();
  EXPECT_GE(seconds, 0.2);
  EXPECT_LT(seconds, 2.5);  // libcurl asks at least once a second while nothing moves
  EXPECT_EQ(server.requests() - requests_before, 1);
  {
    // Already cancelled: no request at all. (The head, fetched at open, is
    // no request either.)
    const ReadCancellationScope scope(&cancelled);
    EXPECT_NE(std::string(ErrorOf([&] { Read(*file, 600000, 100); }).what()).find("read cancelled"), std::string::npos);
    EXPECT_EQ(Read(*file, 0, 100), contents.substr(0, 100));
  }
  EXPECT_EQ(server.requests() - requests_before, 1);
  server.SetScript([](const FakeHttpServer::Request&) { return FakeHttpServer::Behaviour{}; });
  EXPECT_EQ(Read(*file, 400000, 70000), contents.substr(400000, 70000));
}

TEST(HttpFile, AServerThatIsNotThereIsAnIoErrorNamingTheUrl) {
  int port = 0;
  {
    FakeHttpServer gone;  // a port that was free a moment ago and has no listener now
    port = std::stoi(gone.Url("").substr(std::string("http://127.0.0.1:").size()));
  }
  const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/store/manifest.json";
  const Error e = ErrorOf([&] { HttpFile::Open(url, QuickOptions()); });
  EXPECT_EQ(e.kind(), ErrorKind::kIo);
  EXPECT_NE(std::string(e.what()).find(url), std::string::npos) << e.what();
}

TEST(HttpFile, OpenReadableFileTellsUrlsFromPaths) {
  EXPECT_TRUE(IsHttpUrl("http://host/store"));
  EXPECT_TRUE(IsHttpUrl("https://host:8443/a/b"));
  EXPECT_FALSE(IsHttpUrl("/data/http://x"));
  EXPECT_FALSE(IsHttpUrl("store"));
  EXPECT_FALSE(IsHttpUrl("ftp://host/store"));
}

}  // namespace
}  // namespace octocosm
