// IsolatedProcess (ingest/snapshot/isolated_process.h): this test program
// started again as a service answers requests and keeps its state between
// them, and a service that crashes, loops, exits, throws or allocates past
// its cap is reported, while this process goes on.
#include "ingest/snapshot/isolated_process.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "base/error.h"

namespace octocosm {
namespace {

// The service: the request names what to do.
std::string AnswerTestRequest(std::string_view request) {
  static int calls = 0;
  ++calls;
  if (request.substr(0, 5) == "echo:") return std::string(request.substr(5));
  if (request == "calls") return std::to_string(calls);
  if (request == "pid") return std::to_string(getpid());
  if (request == "parent group") return std::to_string(getpgid(0) == getpgid(getppid()));
  if (request == "big") return std::string(3 << 20, 'x');
  if (request == "segfault") {
    NoteIsolatedProgress("first.hdf5");
    NoteIsolatedProgress("second.hdf5");
    std::signal(SIGSEGV, SIG_DFL);  // a sanitizer's handler would report and exit instead
    std::raise(SIGSEGV);
  }
  if (request == "abort") std::abort();
  if (request == "silent") {
    for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
  }
  if (request == "steps") {
    for (int step = 0; step < 12; ++step) {
      NoteIsolatedProgress("step " + std::to_string(step));
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    return "done";
  }
  if (request == "exit") _exit(3);
  if (request == "throw") throw std::runtime_error("no good");
  if (request == "allocate 4 GiB") {
    // Touched: without the cap the service would take it from the machine.
    auto block = std::make_unique<char[]>(std::size_t{4} << 30);
    for (std::size_t i = 0; i < (std::size_t{4} << 30); i += 4096) block[i] = 1;
    return "allocated";
  }
  if (request == "allocate 64 MiB") {
    std::vector<char> block(64 << 20, 1);
    return std::to_string(block.size());
  }
  return "unknown";
}

[[maybe_unused]] const bool kServed = ServeIfStartedAs("isolated-process-test", &AnswerTestRequest);

IsolationLimits Limits(std::chrono::milliseconds time_limit = std::chrono::seconds(30),
                       std::uint64_t extra_address_space = std::uint64_t{1} << 30) {
  IsolationLimits limits;
  limits.time_limit = time_limit;
  limits.extra_address_space = extra_address_space;
  return limits;
}

TEST(IsolatedProcess, AnswersRequestsInOrderAndKeepsItsState) {
  IsolatedProcess service("isolated-process-test");
  for (int i = 1; i <= 3; ++i) {
    const IsolatedResult result = service.Call("calls");
    ASSERT_TRUE(result.returned) << result.failure;
    EXPECT_EQ(result.bytes, std::to_string(i));
  }
  const IsolatedResult binary = service.Call(std::string("echo:hello\0world", 16));
  ASSERT_TRUE(binary.returned) << binary.failure;
  EXPECT_EQ(binary.bytes, std::string("hello\0world", 11));
  EXPECT_TRUE(binary.failure.empty());
}

TEST(IsolatedProcess, AnswersLargerThanASocketBufferArrive) {
  IsolatedProcess service("isolated-process-test");
  for (int i = 0; i < 2; ++i) {
    const IsolatedResult result = service.Call("big");
    ASSERT_TRUE(result.returned) << result.failure;
    EXPECT_EQ(result.bytes, std::string(3 << 20, 'x'));
  }
}

TEST(IsolatedProcess, RunsInAnotherProcessOfItsOwnGroup) {
  IsolatedProcess service("isolated-process-test");
  const IsolatedResult pid = service.Call("pid");
  ASSERT_TRUE(pid.returned) << pid.failure;
  EXPECT_EQ(pid.bytes, std::to_string(service.pid()));
  EXPECT_NE(pid.bytes, std::to_string(getpid()));
  const IsolatedResult group = service.Call("parent group");
  ASSERT_TRUE(group.returned) << group.failure;
  EXPECT_EQ(group.bytes, "0");
}

TEST(IsolatedProcess, ServicesOpenedFromOtherThreadsAreIndependent) {
  std::vector<std::string> answers(4);
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < answers.size(); ++t) {
    threads.emplace_back([&answers, t] {
      IsolatedProcess service("isolated-process-test");
      service.Call("calls");
      answers[t] = service.Call("calls").bytes;
    });
  }
  for (std::thread& thread : threads) thread.join();
  for (const std::string& answer : answers) EXPECT_EQ(answer, "2");
}

TEST(IsolatedProcess, ASegfaultNamesTheSignalAndTheLastNoteAndStaysFailed) {
  IsolatedProcess service("isolated-process-test");
  const IsolatedResult result = service.Call("segfault");
  EXPECT_FALSE(result.returned);
  EXPECT_NE(result.failure.find("was killed by signal 11"), std::string::npos) << result.failure;
  EXPECT_EQ(result.last_note, "second.hdf5");
  const IsolatedResult after = service.Call("calls");
  EXPECT_FALSE(after.returned);
  EXPECT_EQ(after.failure, result.failure);
}

TEST(IsolatedProcess, AnAbortIsReported) {
  IsolatedProcess service("isolated-process-test");
  const IsolatedResult result = service.Call("abort");
  EXPECT_FALSE(result.returned);
  EXPECT_NE(result.failure.find("signal " + std::to_string(SIGABRT)), std::string::npos) << result.failure;
}

TEST(IsolatedProcess, AServiceSilentPastItsTimeLimitIsKilled) {
  const auto start = std::chrono::steady_clock::now();
  IsolatedProcess service("isolated-process-test", Limits(std::chrono::milliseconds(300)));
  const IsolatedResult result = service.Call("silent");
  EXPECT_FALSE(result.returned);
  EXPECT_EQ(result.failure, "went 300 ms without progress and was killed");
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
}

TEST(IsolatedProcess, NotesStartTheTimeLimitAfresh) {
  // 1.2 s in all, never 500 ms without a note.
  IsolatedProcess service("isolated-process-test", Limits(std::chrono::milliseconds(500)));
  const IsolatedResult result = service.Call("steps");
  ASSERT_TRUE(result.returned) << result.failure;
  EXPECT_EQ(result.bytes, "done");
  EXPECT_EQ(result.last_note, "step 11");
}

TEST(IsolatedProcess, AnExitWithoutAnswerIsReported) {
  IsolatedProcess service("isolated-process-test");
  const IsolatedResult result = service.Call("exit");
  EXPECT_FALSE(result.returned);
  EXPECT_EQ(result.failure, "exited with status 3");
}

TEST(IsolatedProcess, AnExceptionIsReportedByItsMessage) {
  IsolatedProcess service("isolated-process-test");
  const IsolatedResult result = service.Call("throw");
  EXPECT_FALSE(result.returned);
  EXPECT_EQ(result.failure, "threw no good");
}

TEST(IsolatedProcess, AnAllocationPastTheCapFailsInTheService) {
  IsolatedProcess service("isolated-process-test", Limits(std::chrono::seconds(30), std::uint64_t{256} << 20));
  const IsolatedResult result = service.Call("allocate 4 GiB");
  EXPECT_FALSE(result.returned);
  // std::bad_alloc; under AddressSanitizer its out-of-memory report and exit.
  EXPECT_FALSE(result.failure.empty());
}

TEST(IsolatedProcess, TheCapLeavesRoomForWhatTheServiceNeeds) {
  IsolatedProcess service("isolated-process-test", Limits(std::chrono::seconds(30), std::uint64_t{256} << 20));
  const IsolatedResult result = service.Call("allocate 64 MiB");
  ASSERT_TRUE(result.returned) << result.failure;
  EXPECT_EQ(result.bytes, std::to_string(64 << 20));
}

TEST(IsolatedProcess, TheServiceEndsWithItsOwner) {
  pid_t pid = -1;
  {
    IsolatedProcess service("isolated-process-test");
    ASSERT_TRUE(service.Call("calls").returned);
    pid = service.pid();
    EXPECT_EQ(kill(pid, 0), 0);
  }
  // Reaped: no such process, not even a zombie.
  EXPECT_EQ(kill(pid, 0), -1);
}

TEST(IsolatedProcess, AProgramThatCannotStartIsAnIoErrorNamingIt) {
  SetIsolatedProgram("/nonexistent/octocosm");
  try {
    IsolatedProcess service("isolated-process-test");
    ADD_FAILURE() << "started";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::kIo);
    EXPECT_NE(std::string(e.what()).find("cannot start /nonexistent/octocosm as the isolated-process-test process"),
              std::string::npos)
        << e.what();
  }
  SetIsolatedProgram("/proc/self/exe");
  IsolatedProcess service("isolated-process-test");
  EXPECT_TRUE(service.Call("calls").returned);
}

TEST(IsolatedProcess, NotesOutsideAServiceDoNothing) {
  NoteIsolatedProgress("ignored");
  IsolatedProcess service("isolated-process-test");
  const IsolatedResult result = service.Call("echo:ok");
  ASSERT_TRUE(result.returned);
  EXPECT_TRUE(result.last_note.empty());
}

}  // namespace
}  // namespace octocosm
