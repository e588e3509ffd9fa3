// CallIsolated (tools/snapshot/isolated_call.h): a function run in a child
// process returns its bytes, and a child that crashes, loops, exits, throws
// or allocates past its cap is reported, while this process goes on.
#include "ingest/snapshot/isolated_call.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <memory>
#include <string>
#include <thread>
#include <vector>

namespace octocosm {
namespace {

TEST(IsolatedCall, ReturnsTheChildsBytes) {
  const IsolatedResult result = CallIsolated([] { return std::string("hello\0world", 11); });
  ASSERT_TRUE(result.returned) << result.failure;
  EXPECT_EQ(result.bytes, std::string("hello\0world", 11));
  EXPECT_TRUE(result.failure.empty());
}

TEST(IsolatedCall, ReturnsMoreBytesThanAPipeHolds) {
  // Larger than the pipe's buffer: the parent reads while the child writes.
  const std::string big(3 << 20, 'x');
  const IsolatedResult result = CallIsolated([&] { return big; });
  ASSERT_TRUE(result.returned) << result.failure;
  EXPECT_EQ(result.bytes, big);
}

TEST(IsolatedCall, RunsInAnotherProcess) {
  const pid_t self = getpid();
  const IsolatedResult result = CallIsolated([] { return std::to_string(getpid()); });
  ASSERT_TRUE(result.returned) << result.failure;
  EXPECT_NE(result.bytes, std::to_string(self));
}

TEST(IsolatedCall, ASegfaultNamesTheSignalAndTheLastNote) {
  const IsolatedResult result = CallIsolated([]() -> std::string {
    NoteIsolatedProgress("first.hdf5");
    NoteIsolatedProgress("second.hdf5");
    std::signal(SIGSEGV, SIG_DFL);  // a sanitizer's handler would report and exit instead
    std::raise(SIGSEGV);
    return "unreachable";
  });
  EXPECT_FALSE(result.returned);
  EXPECT_NE(result.failure.find("was killed by signal 11"), std::string::npos) << result.failure;
  EXPECT_EQ(result.last_note, "second.hdf5");
}

TEST(IsolatedCall, AnAbortIsReported) {
  const IsolatedResult result = CallIsolated([]() -> std::string { std::abort(); });
  EXPECT_FALSE(result.returned);
  EXPECT_NE(result.failure.find("signal " + std::to_string(SIGABRT)), std::string::npos) << result.failure;
}

TEST(IsolatedCall, AChildSilentPastItsTimeLimitIsKilled) {
  const auto start = std::chrono::steady_clock::now();
  IsolationLimits limits;
  limits.time_limit = std::chrono::milliseconds(300);
  const IsolatedResult result = CallIsolated(
      []() -> std::string {
        for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
      },
      limits);
  EXPECT_FALSE(result.returned);
  EXPECT_EQ(result.failure, "went 300 ms without progress and was killed");
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
}

TEST(IsolatedCall, NotesStartTheTimeLimitAfresh) {
  IsolationLimits limits;
  limits.time_limit = std::chrono::milliseconds(500);
  // 1.2 s in all, never 500 ms without a note.
  const IsolatedResult result = CallIsolated(
      [] {
        for (int step = 0; step < 12; ++step) {
          NoteIsolatedProgress("step " + std::to_string(step));
          std::this_thread::sleep_for(std::chrono::milliseconds(100));
        }
        return std::string("done");
      },
      limits);
  ASSERT_TRUE(result.returned) << result.failure;
  EXPECT_EQ(result.bytes, "done");
  EXPECT_EQ(result.last_note, "step 11");
}

TEST(IsolatedCall, AnExitWithoutResultIsReported) {
  const IsolatedResult result = CallIsolated([]() -> std::string { _exit(3); });
  EXPECT_FALSE(result.returned);
  EXPECT_EQ(result.failure, "exited with status 3");
}

TEST(IsolatedCall, AnExceptionIsReportedByItsMessage) {
  const IsolatedResult result = CallIsolated([]() -> std::string { throw std::runtime_error("no good"); });
  EXPECT_FALSE(result.returned);
  EXPECT_EQ(result.failure, "threw no good");
}

TEST(IsolatedCall, AnAllocationPastTheCapFailsInTheChild) {
  IsolationLimits limits;
  limits.extra_address_space = std::uint64_t{256} << 20;
  // 4 GiB, touched: without the cap the child would take it from the machine.
  const IsolatedResult result = CallIsolated(
      []() -> std::string {
        auto block = std::make_unique<char[]>(std::size_t{4} << 30);
        for (std::size_t i = 0; i < (std::size_t{4} << 30); i += 4096) block[i] = 1;
        return "allocated";
      },
      limits);
  EXPECT_FALSE(result.returned);
  // std::bad_alloc; under AddressSanitizer its out-of-memory report and exit.
  EXPECT_FALSE(result.failure.empty());
}

TEST(IsolatedCall, TheCapLeavesRoomForWhatTheChildNeeds) {
  IsolationLimits limits;
  limits.extra_address_space = std::uint64_t{256} << 20;
  const IsolatedResult result = CallIsolated(
      [] {
        std::vector<char> block(64 << 20, 1);
        return std::to_string(block.size());
      },
      limits);
  ASSERT_TRUE(result.returned) << result.failure;
  EXPECT_EQ(result.bytes, std::to_string(64 << 20));
}

TEST(IsolatedCall, NotesOutsideAChildDoNothing) {
  NoteIsolatedProgress("ignored");
  const IsolatedResult result = CallIsolated([] { return std::string("ok"); });
  ASSERT_TRUE(result.returned);
  EXPECT_TRUE(result.last_note.empty());
}

}  // namespace
}  // namespace octocosm
