// A store served by nginx as a static directory reads as the local one: the
// program's info, verify, query, follow and render give the same bytes from
// the URL as from the directory, and each fault of a server (no store there,
// refused access, ranges ignored, no server, a damaged copy) is an error
// that names the URL and says what is wrong.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <string>
#include <thread>

#include "tests/support/nginx_server.h"
#include "tests/support/program_run.h"
#include "tests/support/temp_dir.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using testing_support::NginxServer;
using testing_support::ProgramRun;
using testing_support::ReadText;

constexpr int kProgramSeconds = 300;

struct Served {
  testing_support::TempDir dir{"remote-store-test"};
  fs::path root;          // what nginx serves
  fs::path local_store;   // root/store
  std::unique_ptr<NginxServer> nginx;
  std::string setup_error;
};

Served* served = nullptr;

ProgramRun RunOctocosm(const std::string& args) {
  return testing_support::RunCommand(std::string(OCTOCOSM_BINARY) + " " + args, kProgramSeconds,
                                     served->dir.path() / "command.log");
}

class RemoteStoreTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    served = new Served;
    served->root = served->dir.path() / "www";
    served->local_store = served->root / "store";
    const fs::path sim = served->dir.path() / "sim";
    ProgramRun run = RunOctocosm("synth pm -o " + sim.string() + " -N 16 --outputs 3 --steps 6 --quiet");
    if (run.status != 0) {
      served->setup_error = "synth: " + run.Describe();
      return;
    }
    run = RunOctocosm("ingest " + (sim / "snap_000").string() + " " + (sim / "snap_001").string() + " " +
              (sim / "snap_002").string() + " -o " + served->local_store.string() +
              " --capacity 300 --neighbours 8 --quiet");
    if (run.status != 0) {
      served->setup_error = "ingest: " + run.Describe();
      return;
    }
    // Copies behind the locations that refuse ranges and access, and one
    // with a damaged block.
    for (const char* where : {"norange", "forbidden", "damaged"}) {
      fs::create_directories(served->root / where);
      fs::copy(served->local_store, served->root / where / "store", fs::copy_options::recursive);
    }
    served->nginx = std::make_unique<NginxServer>(served->root, served->dir.path() / "nginx");
  }
  static void TearDownTestSuite() {
    delete served;
    served = nullptr;
  }
  void SetUp() override {
    ASSERT_TRUE(served->setup_error.empty()) << served->setup_error;
    if (!served->nginx->started()) GTEST_SKIP() << served->nginx->error();
  }

  static std::string Url(const std::string& path) { return served->nginx->Url(path); }
  static fs::path Out(const std::string& name) { return served->dir.path() / name; }
};

TEST_F(RemoteStoreTest, InfoAndVerifyReadTheStoreOverHttp) {
  const ProgramRun local = RunOctocosm("info " + served->local_store.string());
  const ProgramRun remote = RunOctocosm("info " + Url("/store"));
  ASSERT_EQ(local.status, 0) << local.Describe();
  ASSERT_EQ(remote.status, 0) << remote.Describe();
  // The same report but for the store's name in its first line.
  const auto body = [](const std::string& text) { return text.substr(text.find('\n')); };
  EXPECT_EQ(body(remote.output), body(local.output));
  EXPECT_NE(remote.output.find("store " + Url("/store")), std::string::npos) << remote.output;

  const ProgramRun verify = RunOctocosm("verify " + Url("/store"));
  EXPECT_EQ(verify.status, 0) << verify.Describe();
  EXPECT_NE(verify.output.find("verified " + Url("/store")), std::string::npos) << verify.output;
}

TEST_F(RemoteStoreTest, QueryAndFollowGiveTheLocalBytes) {
  for (const std::string& args : {std::string(" --epoch 2 --level 2 --columns id,velocity --format bin"),
                                  std::string(" --epoch 1 --sphere 50000,50000,50000,30000 --level 1"),
                                  std::string(" --epoch 0 --frustum --camera 50000,50000,250000 --error 3")}) {
    const ProgramRun local = RunOctocosm("query " + served->local_store.string() + args + " -q -o " + Out("local.q").string());
    const ProgramRun remote = RunOctocosm("query " + Url("/store") + args + " -q -o " + Out("remote.q").string());
    ASSERT_EQ(local.status, 0) << local.Describe();
    ASSERT_EQ(remote.status, 0) << remote.Describe();
    const std::string expected = ReadText(Out("local.q"));
    EXPECT_GT(expected.size(), 100u) << args;
    EXPECT_TRUE(ReadText(Out("remote.q")) == expected) << args;
  }
  {
    std::ofstream ids(Out("ids.txt"));
    ids << "1\n77\n2000\n4095\n999999\n";
  }
  const ProgramRun local = RunOctocosm("follow " + served->local_store.string() + " --ids " + Out("ids.txt").string() +
                               " -o " + Out("local.follow").string());
  const ProgramRun remote =
      RunOctocosm("follow " + Url("/store") + " --ids " + Out("ids.txt").string() + " -o " + Out("remote.follow").string());
  ASSERT_EQ(local.status, 0) << local.Describe();
  ASSERT_EQ(remote.status, 0) << remote.Describe();
  EXPECT_GT(ReadText(Out("local.follow")).size(), 50u);
  EXPECT_TRUE(ReadText(Out("remote.follow")) == ReadText(Out("local.follow")));
}

TEST_F(RemoteStoreTest, RenderGivesTheLocalPicture) {
  const std::string args = " --time 1.4 --error 2 --width 320 --height 180 --select " + Out("select.txt").string();
  {
    std::ofstream ids(Out("select.txt"));
    for (int id = 0; id < 4096; id += 9) ids << id << "\n";
  }
  for (const std::string extension : {".png", ".pfm"}) {
    const ProgramRun local = RunOctocosm("render " + served->local_store.string() + args + " -o " + Out("local" + extension).string());
    const ProgramRun remote = RunOctocosm("render " + Url("/store") + args + " -o " + Out("remote" + extension).string());
    ASSERT_EQ(local.status, 0) << local.Describe();
    ASSERT_EQ(remote.status, 0) << remote.Describe();
    const std::string expected = ReadText(Out("local" + extension));
    EXPECT_GT(expected.size(), 1000u);
    EXPECT_TRUE(ReadText(Out("remote" + extension)) == expected) << extension;
  }
}

TEST_F(RemoteStoreTest, NoStoreAtTheUrlIsNotFound) {
  const ProgramRun run = RunOctocosm("info " + Url("/elsewhere/store"));
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find(Url("/elsewhere/store") + ": the server has no manifest.json there"), std::string::npos)
      << run.output;
}

TEST_F(RemoteStoreTest, RefusedAccessSaysSo) {
  const ProgramRun run = RunOctocosm("info " + Url("/forbidden/store"));
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find(Url("/forbidden/store/manifest.json")), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("the server refuses access (HTTP 403)"), std::string::npos) << run.output;
}

TEST_F(RemoteStoreTest, AServerWithoutRangeRequestsIsRefused) {
  const ProgramRun run = RunOctocosm("info " + Url("/norange/store"));
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find(Url("/norange/store/epoch-00000.pages")), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("ignored the range request"), std::string::npos) << run.output;
}

TEST_F(RemoteStoreTest, NoServerIsAnErrorNamingTheUrl) {
  // nginx's port once it is stopped: nothing listens there.
  int port = 0;
  {
    NginxServer brief(served->root, served->dir.path() / "brief");
    ASSERT_TRUE(brief.started()) << brief.error();
    port = brief.port();
  }
  const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/store";
  const ProgramRun run = RunOctocosm("info " + url);
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find(url + "/manifest.json"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("gave up after"), std::string::npos) << run.output;
}

TEST_F(RemoteStoreTest, ADamagedBlockOnTheServerIsCorruptionNamingTheUrl) {
  // Flip a byte of the first block of epoch 0, which follows the header page.
  const fs::path pages = served->root / "damaged" / "store" / "epoch-00000.pages";
  std::fstream file(pages, std::ios::in | std::ios::out | std::ios::binary);
  const std::streamoff at = 4096 + 100;
  file.seekg(at);
  char byte = 0;
  file.read(&byte, 1);
  byte = static_cast<char>(byte ^ 0x5a);
  file.seekp(at);
  file.write(&byte, 1);
  file.close();
  const ProgramRun run = RunOctocosm("verify " + Url("/damaged/store"));
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find(Url("/damaged/store/epoch-00000.pages")), std::string::npos) << run.output;
  EXPECT_TRUE(std::regex_search(run.output, std::regex("checksum|corrupt")));
  // The renderer reads blocks near one another with one request: the damaged
  // one among them is still the one named.
  const ProgramRun render = RunOctocosm("render " + Url("/damaged/store") + " --time 0 --error 0.5 --width 320 --height 180 -o " +
                                        Out("damaged.png").string());
  EXPECT_NE(render.status, 0);
  EXPECT_NE(render.output.find(Url("/damaged/store/epoch-00000.pages")), std::string::npos) << render.output;
  EXPECT_TRUE(std::regex_search(render.output, std::regex("checksum|corrupt"))) << render.output;
}

// `octocosm serve` runs nginx on a directory until a signal ends it.
TEST_F(RemoteStoreTest, ServeRunsNginxOnADirectoryUntilStopped) {
  const int port = NginxServer::FreePort();
  const std::string log = (served->dir.path() / "serve.log").string();
  const pid_t serve = ::fork();
  if (serve == 0) {
    ::freopen(log.c_str(), "w", stdout);
    ::execl(OCTOCOSM_BINARY, OCTOCOSM_BINARY, "serve", served->root.c_str(), "--port", std::to_string(port).c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ASSERT_TRUE(NginxServer::WaitUntilListening(port)) << ReadText(log);
  const std::string url = "http://127.0.0.1:" + std::to_string(port) + "/store";
  const ProgramRun local = RunOctocosm("query " + served->local_store.string() + " --epoch 1 --level 1 -q");
  const ProgramRun remote = RunOctocosm("query " + url + " --epoch 1 --level 1 -q");
  EXPECT_EQ(remote.status, 0) << remote.Describe();
  EXPECT_EQ(remote.output, local.output);
  ::kill(serve, SIGTERM);
  int status = 0;
  ::waitpid(serve, &status, 0);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGTERM) << status;
  const std::string listing = ReadText(log);
  EXPECT_NE(listing.find("store: " + url + "\n"), std::string::npos) << listing;
  EXPECT_EQ(listing.find("/store/ids"), std::string::npos) << "a store's ID index is not listed:\n" << listing;
  // nginx went with it: nothing listens any more.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const ProgramRun after = RunOctocosm("info " + url);
  EXPECT_NE(after.status, 0);
}

TEST_F(RemoteStoreTest, IngestWritesOnlyLocalDirectories) {
  const ProgramRun run = RunOctocosm("ingest " + (served->dir.path() / "sim" / "snap_000").string() + " -o " +
                                     Url("/new-store") + " --quiet");
  EXPECT_NE(run.status, 0);
  EXPECT_NE(run.output.find("a store is written to a local directory"), std::string::npos) << run.output;
  EXPECT_FALSE(fs::exists("http:"));
}

}  // namespace
}  // namespace octocosm
