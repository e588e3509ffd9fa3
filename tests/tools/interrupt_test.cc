// Interrupted and failed runs of the octocosm program leave nothing behind:
// ingest stopped by a signal (base/interrupt_cleanup.h), a rerun after
// kill -9 (the locks of storage/store_writer.h and base/temp_directory.h),
// and output files that appear whole or not at all (tools/output_file.h).
// The program runs as a child process (OCTOCOSM_BINARY), as a user runs it.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "base/temp_directory.h"
#include "index/dataset.h"
#include "index/morton.h"
#include "storage/store_writer.h"
#include "tests/support/temp_dir.h"
#include "tools/output_file.h"

extern char** environ;

namespace octocosm {
namespace {

namespace fs = std::filesystem;

std::string ReadText(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

void WriteText(const fs::path& path, const std::string& text) { std::ofstream(path) << text; }

std::vector<std::string> Entries(const fs::path& directory) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(directory)) names.push_back(entry.path().filename());
  std::sort(names.begin(), names.end());
  return names;
}

bool AnyEntryStartsWith(const fs::path& directory, const std::string& prefix) {
  for (const std::string& name : Entries(directory)) {
    if (name.rfind(prefix, 0) == 0) return true;
  }
  return false;
}

// The program, started with its output (stdout and stderr) going to `log`.
pid_t StartOctocosm(const std::vector<std::string>& args, const fs::path& log) {
  std::vector<std::string> argv_strings = {OCTOCOSM_BINARY};
  argv_strings.insert(argv_strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& s : argv_strings) argv.push_back(s.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  pid_t pid = -1;
  const int error = posix_spawn(&pid, OCTOCOSM_BINARY, &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  EXPECT_EQ(error, 0) << "posix_spawn " << OCTOCOSM_BINARY;
  return error == 0 ? pid : -1;
}

int WaitFor(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return status;
}

struct ProgramRun {
  int exit_status = -1;  // -1: ended by a signal
  std::string output;
};

ProgramRun RunOctocosm(const std::vector<std::string>& args, const fs::path& log) {
  const int status = WaitFor(StartOctocosm(args, log));
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, ReadText(log)};
}

// Waits until `directory` holds an entry whose name starts with `prefix`:
// the ingest is under way, its temporary directory made.
bool WaitForEntry(const fs::path& directory, const std::string& prefix, pid_t pid) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (std::chrono::steady_clock::now() < deadline) {
    std::error_code error;
    if (fs::is_directory(directory, error) && AnyEntryStartsWith(directory, prefix)) return true;
    if (::waitpid(pid, nullptr, WNOHANG) == pid) return false;  // ended already
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

class InterruptTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    data_ = new testing_support::TempDir("interrupt-test");
    const fs::path log = data_->path() / "setup.log";
    // Large enough that ingest (one thread, a small budget: the neighbour
    // pass and the chunks spill to temporary files) runs for seconds.
    ProgramRun run = RunOctocosm({"synth", "scale", "-o", (data_->path() / "large").string(), "-n", "500000", "-q"}, log);
    ASSERT_EQ(run.exit_status, 0) << run.output;
    // Small, for the runs that must finish.
    run = RunOctocosm({"synth", "pm", "-o", (data_->path() / "small").string(), "-N", "16", "--outputs", "2", "-q"}, log);
    ASSERT_EQ(run.exit_status, 0) << run.output;
  }
  static void TearDownTestSuite() {
    delete data_;
    data_ = nullptr;
  }

  static std::string Large() { return (data_->path() / "large" / "snap").string(); }
  static std::string Small(int epoch) { return (data_->path() / "small" / ("snap_00" + std::to_string(epoch))).string(); }
  fs::path Log() const { return dir_.path() / "octocosm.log"; }

  // Starts ingesting the large snapshot into `output`, waits until its
  // temporary directory appears in `temp_parent` and some work is done, then
  // sends `signal_number`; returns the wait status.
  int IngestAndSignal(const fs::path& output, const fs::path& temp_parent, int signal_number,
                      std::vector<std::string> extra = {}) {
    std::vector<std::string> args = {"ingest", Large(), "-o", output.string(), "--threads", "1", "--memory", "64M", "-q"};
    args.insert(args.end(), extra.begin(), extra.end());
    const pid_t pid = StartOctocosm(args, Log());
    if (pid < 0) return -1;
    const bool started = WaitForEntry(temp_parent, "octocosm-ingest-", pid);
    if (started) std::this_thread::sleep_for(std::chrono::milliseconds(300));
    ::kill(pid, signal_number);
    const int status = WaitFor(pid);
    EXPECT_TRUE(started) << "the ingest ended before it could be interrupted:\n" << ReadText(Log());
    return status;
  }

  static inline testing_support::TempDir* data_ = nullptr;
  testing_support::TempDir dir_{"interrupt-case"};
};

TEST_F(InterruptTest, SigtermRemovesTheOutputTheRunCreated) {
  const fs::path output = dir_.path() / "store";
  const int status = IngestAndSignal(output, output, SIGTERM);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM) << status << "\n" << ReadText(Log());
  EXPECT_FALSE(fs::exists(output)) << ::testing::PrintToString(Entries(output));
  EXPECT_NE(ReadText(Log()).find("interrupted by SIGTERM"), std::string::npos) << ReadText(Log());
  EXPECT_EQ(Entries(dir_.path()), std::vector<std::string>{"octocosm.log"});
}

TEST_F(InterruptTest, SigintLeavesAnExistingOutputDirectoryAsItWas) {
  const fs::path output = dir_.path() / "store";
  fs::create_directories(output);
  WriteText(output / "notes.txt", "the user's");
  const int status = IngestAndSignal(output, output, SIGINT);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGINT) << status << "\n" << ReadText(Log());
  EXPECT_EQ(Entries(output), std::vector<std::string>{"notes.txt"});
  EXPECT_EQ(ReadText(output / "notes.txt"), "the user's");
}

TEST_F(InterruptTest, SighupRemovesTheTemporaryDirectoryUnderTempDir) {
  const fs::path output = dir_.path() / "store";
  const fs::path temp = dir_.path() / "scratch";
  const int status = IngestAndSignal(output, temp, SIGHUP, {"--temp-dir", temp.string()});
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGHUP) << status << "\n" << ReadText(Log());
  EXPECT_TRUE(Entries(temp).empty()) << ::testing::PrintToString(Entries(temp));
  EXPECT_FALSE(fs::exists(output));
}

// kill -9 removes nothing; the next run into the same output recognises what
// it left by the unheld locks, removes it and succeeds.
TEST_F(InterruptTest, ARerunAfterKillMinus9RemovesTheAbandonedFilesAndSucceeds) {
  const fs::path output = dir_.path() / "store";
  const int status = IngestAndSignal(output, output, SIGKILL);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << status;
  ASSERT_TRUE(AnyEntryStartsWith(output, "octocosm-ingest-"));
  ASSERT_TRUE(fs::exists(output / kWriterLockFileName));

  const ProgramRun rerun = RunOctocosm({"ingest", Small(0), Small(1), "-o", output.string(), "-q"}, Log());
  ASSERT_EQ(rerun.exit_status, 0) << rerun.output;
  EXPECT_EQ(Entries(output),
            (std::vector<std::string>{"epoch-00000.pages", "epoch-00001.pages", "ids", "manifest.json"}));
  EXPECT_EQ(Dataset::Open(output.string()).epoch_count(), 2u);
}

// The same, with the abandoned files made by hand; beside them a directory
// of the temporary pattern that no lock claims, which is not removed.
TEST_F(InterruptTest, ARerunRemovesHandMadeAbandonedTemporariesAndNothingElse) {
  const fs::path output = dir_.path() / "store";
  fs::create_directories(output / "octocosm-ingest-abc123");
  WriteText(output / "octocosm-ingest-abc123" / TempDirectory::kLockFileName, "");
  WriteText(output / "octocosm-ingest-abc123" / "chunk-0.pts", "spilled points");
  WriteText(output / kWriterLockFileName, "pid 1\n");
  WriteText(output / "epoch-00000.pages", "half a page file");
  WriteText(output / "epoch-00001.pages.tmp", "a page file being written");
  fs::create_directories(output / "octocosm-ingest-nolock");
  WriteText(output / "octocosm-ingest-nolock" / "data", "not claimed by a lock");

  const ProgramRun rerun = RunOctocosm({"ingest", Small(0), "-o", output.string(), "-q"}, Log());
  ASSERT_EQ(rerun.exit_status, 0) << rerun.output;
  EXPECT_EQ(Entries(output), (std::vector<std::string>{"epoch-00000.pages", "ids", "manifest.json",
                                                       "octocosm-ingest-nolock"}));
  EXPECT_EQ(ReadText(output / "octocosm-ingest-nolock" / "data"), "not claimed by a lock");
  EXPECT_EQ(Dataset::Open(output.string()).epoch_count(), 1u);
}

TEST_F(InterruptTest, StoreFilesNoLockClaimsAreRefusedAndKept) {
  const fs::path output = dir_.path() / "store";
  fs::create_directories(output);
  WriteText(output / "epoch-00000.pages", "someone's");
  const ProgramRun run = RunOctocosm({"ingest", Small(0), "-o", output.string(), "-q"}, Log());
  EXPECT_EQ(run.exit_status, 2) << run.output;
  EXPECT_NE(run.output.find("already holds store file epoch-00000.pages"), std::string::npos) << run.output;
  EXPECT_EQ(Entries(output), std::vector<std::string>{"epoch-00000.pages"});
}

TEST_F(InterruptTest, AnIngestWhoseParentIsReadOnlyWritesOnlyInsideTheOutput) {
  if (::geteuid() == 0) GTEST_SKIP() << "root writes into read-only directories";
  const fs::path parent = dir_.path() / "read-only";
  const fs::path output = parent / "store";
  fs::create_directories(output);
  fs::permissions(parent, fs::perms::owner_read | fs::perms::owner_exec);
  const ProgramRun run = RunOctocosm({"ingest", Small(0), "-o", output.string(), "-q"}, Log());
  fs::permissions(parent, fs::perms::owner_all);
  EXPECT_EQ(run.exit_status, 0) << run.output;
}

TEST_F(InterruptTest, SigtermRemovesTheSnapshotFilesSynthWasWriting) {
  const fs::path output = dir_.path() / "snapshot";
  const pid_t pid = StartOctocosm({"synth", "scale", "-o", output.string(), "-n", "4000000", "-q"}, Log());
  ASSERT_GT(pid, 0);
  const bool started = WaitForEntry(output, "snap", pid);
  ::kill(pid, SIGTERM);
  const int status = WaitFor(pid);
  ASSERT_TRUE(started) << "synth ended before it could be interrupted:\n" << ReadText(Log());
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM) << status << "\n" << ReadText(Log());
  EXPECT_TRUE(Entries(output).empty()) << ::testing::PrintToString(Entries(output));
}

TEST_F(InterruptTest, AnAbsurdPageSizeNamesTheFlagAndTheValue) {
  for (const std::string value : {"4G", "1e400", "3K"}) {
    const ProgramRun run = RunOctocosm({"ingest", Small(0), "-o", (dir_.path() / "store").string(), "--page-size", value}, Log());
    EXPECT_EQ(run.exit_status, 2) << run.output;
    EXPECT_NE(run.output.find("--page-size '" + value + "'"), std::string::npos) << run.output;
    EXPECT_FALSE(fs::exists(dir_.path() / "store"));
  }
}

// A query or follow stopped by corruption exits 3 and writes no file, nor
// touches one already there.
TEST_F(InterruptTest, OutputsOfARunStoppedByCorruptionDoNotAppear) {
  const fs::path store = dir_.path() / "store";
  ProgramRun run = RunOctocosm({"ingest", Small(0), Small(1), "-o", store.string(), "-q"}, Log());
  ASSERT_EQ(run.exit_status, 0) << run.output;
  const fs::path ids = dir_.path() / "ids.txt";
  WriteText(ids, "1\n2\n");
  const fs::path outputs = dir_.path() / "outputs";
  fs::create_directories(outputs);
  run = RunOctocosm({"query", store.string(), "--level", "3", "-o", (outputs / "fresh.csv").string()}, Log());
  ASSERT_EQ(run.exit_status, 0) << run.output;
  fs::remove(outputs / "fresh.csv");
  {
    // The one block of each epoch damaged in every sixteenth, so that
    // whichever of its columns a reader decodes fails its checksum.
    const Dataset dataset = Dataset::Open(store.string());
    for (std::uint32_t epoch = 0; epoch < 2; ++epoch) {
      const auto entry = *dataset.store().Lookup({epoch, NodeKey::Root().value()});
      std::fstream f(store / dataset.store().epochs()[epoch].file, std::ios::in | std::ios::out | std::ios::binary);
      for (std::uint64_t part = 1; part < 16; ++part) {
        f.seekp(static_cast<std::streamoff>(entry.first_page * dataset.store().page_size() +
                                            entry.byte_length * part / 16));
        f.put('\x5a');
      }
    }
  }
  WriteText(outputs / "old.csv", "an earlier result\n");
  for (const std::string name : {"fresh.csv", "old.csv"}) {
    const std::string path = (outputs / name).string();
    run = RunOctocosm({"query", store.string(), "--level", "3", "-o", path}, Log());
    EXPECT_EQ(run.exit_status, 3) << run.output;
    run = RunOctocosm({"query", store.string(), "--epoch", "1", "--level", "3", "--format", "ply", "-o", path}, Log());
    EXPECT_EQ(run.exit_status, 3) << run.output;
    run = RunOctocosm({"follow", store.string(), "--ids", ids.string(), "-o", path}, Log());
    EXPECT_EQ(run.exit_status, 3) << run.output;
  }
  EXPECT_EQ(Entries(outputs), std::vector<std::string>{"old.csv"});
  EXPECT_TRUE(ReadText(outputs / "old.csv") == "an earlier result\n") << "old.csv was replaced";
}

TEST(TempDirectory, RemovesOnlyAbandonedDirectoriesOfItsPrefix) {
  testing_support::TempDir dir("temp-directory");
  const fs::path parent = dir.path();
  fs::create_directories(parent / "job-dead01");
  WriteText(parent / "job-dead01" / TempDirectory::kLockFileName, "");
  WriteText(parent / "job-dead01" / "spill", "x");
  fs::create_directories(parent / "job-nolock");  // maybe still being made
  fs::create_directories(parent / "other-dead02");
  WriteText(parent / "other-dead02" / TempDirectory::kLockFileName, "");
  fs::create_directories(parent / "job-toolongname");
  WriteText(parent / "job-toolongname" / TempDirectory::kLockFileName, "");
  std::string live_path;
  {
    TempDirectory live(parent.string(), "job");  // itself removes job-dead01 first
    live_path = live.path();
    EXPECT_TRUE(fs::exists(fs::path(live_path) / TempDirectory::kLockFileName));
    EXPECT_FALSE(fs::exists(parent / "job-dead01"));
    // A live owner's lock holds, even against a sweep in the same process.
    EXPECT_EQ(TempDirectory::RemoveAbandoned(parent.string(), "job"), 0);
    EXPECT_TRUE(fs::exists(live_path));
  }
  EXPECT_FALSE(fs::exists(live_path));
  EXPECT_EQ(Entries(parent), (std::vector<std::string>{"job-nolock", "job-toolongname", "other-dead02"}));
}

TEST(OutputFile, AppearsOnlyWhenCommitted) {
  testing_support::TempDir dir("output-file");
  const fs::path path = dir.path() / "points.csv";
  {
    OutputFile output(path.string());
    EXPECT_NE(output.write_path(), path.string());
    WriteText(output.write_path(), "half");
    EXPECT_FALSE(fs::exists(path));
  }  // an error: never committed
  EXPECT_TRUE(Entries(dir.path()).empty()) << ::testing::PrintToString(Entries(dir.path()));

  WriteText(path, "old");
  {
    OutputFile output(path.string());
    WriteText(output.write_path(), "new");
    EXPECT_EQ(ReadText(path), "old");
    output.Commit();
  }
  EXPECT_EQ(ReadText(path), "new");
  EXPECT_EQ(Entries(dir.path()), std::vector<std::string>{"points.csv"});

  // A link is followed: its target replaced, the link kept.
  fs::create_symlink(path, dir.path() / "link.csv");
  {
    OutputFile output((dir.path() / "link.csv").string());
    WriteText(output.write_path(), "through the link");
    output.Commit();
  }
  EXPECT_TRUE(fs::is_symlink(dir.path() / "link.csv"));
  EXPECT_EQ(ReadText(path), "through the link");

  // What is not a regular file is written directly.
  OutputFile null_device("/dev/null");
  EXPECT_EQ(null_device.write_path(), "/dev/null");
  null_device.Commit();
  EXPECT_TRUE(fs::is_character_file("/dev/null"));
}

}  // namespace
}  // namespace octocosm
