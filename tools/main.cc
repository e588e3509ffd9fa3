// octocosm: the command-line front end. Reads as a list of subcommands; each
// lives in its own file (tools/cmd_*.cc). Deep code throws octocosm::Error;
// only here does an error become a message and an exit status.
#include <cstdio>
#include <exception>
#include <new>
#include <system_error>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "base/huge_pages.h"
#include "base/interrupt_cleanup.h"
#include "tools/commands.h"

namespace {

// Exit statuses, documented in --help.
int ExitStatusFor(octocosm::ErrorKind kind) {
  switch (kind) {
    case octocosm::ErrorKind::kInvalidArgument: return 2;
    case octocosm::ErrorKind::kCorruption: return 3;
    case octocosm::ErrorKind::kBadInput: return 4;
    case octocosm::ErrorKind::kNotFound: return 5;
    case octocosm::ErrorKind::kNotSupported: return 6;
    case octocosm::ErrorKind::kIo: return 7;
  }
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  octocosm::ReexecuteIngestWithHugePages(argc, argv);
  // Before any thread starts; after the re-execution, which would pass the
  // blocked signals on to the new program.
  octocosm::InstallInterruptCleanup();
  CLI::App app{"octocosm: an out-of-core level-of-detail octree store for N-body snapshots"};
  app.footer(
      "Exit status: 0 success, 1 other failure, 2 bad arguments, 3 corrupt store, 4 malformed input,\n"
      "5 not found, 6 unsupported format version, 7 I/O error.\n"
      "Run 'octocosm SUBCOMMAND --help' for the flags of each subcommand.");
  app.require_subcommand(1);
  app.set_version_flag("--version", "octocosm 0.1.0");
  octocosm::AddIngestCommand(app);
  octocosm::AddInfoCommand(app);
  octocosm::AddVerifyCommand(app);
  octocosm::AddSynthCommand(app);
  octocosm::AddQueryCommand(app);
  octocosm::AddFollowCommand(app);
  octocosm::AddRenderCommand(app);
  octocosm::AddViewCommand(app);
  octocosm::AddServeCommand(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const octocosm::Error& e) {
    std::fprintf(stderr, "octocosm: %s\n", e.what());
    return ExitStatusFor(e.kind());
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "octocosm: error: out of memory (a memory limit such as ulimit -v, or --memory too large?)\n");
    return 1;
  } catch (const std::system_error& e) {
    // What a thread that could not start throws: "Resource temporarily
    // unavailable" alone would not say what ran out.
    const bool resources = e.code() == std::errc::resource_unavailable_try_again ||
                           e.code() == std::errc::not_enough_memory;
    std::fprintf(stderr, "octocosm: error: %s%s\n", e.what(),
                 resources ? " (could not start a thread or reserve memory: a memory or process limit such as "
                             "ulimit -v or ulimit -u?)"
                           : "");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "octocosm: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
