// A deterministic mutation driver for one fuzz target, for builds without
// libFuzzer (gcc, plain or with the sanitizers): it feeds the target its
// seeds, then a fixed number of mutants of them, each drawn from a generator
// seeded by the run's seed and the iteration number, so that any iteration
// can be replayed alone. Mutations: byte and bit flips, truncations, erased
// and duplicated ranges, splices of another seed, and interesting integers
// and floats (0, -1, 2^31, 2^63, NaN, inf...) written over a random offset,
// in either byte order. Offsets favour the first 512 bytes, where the
// headers are.
//
//   NAME_fuzz_driver [--iterations N] [--seed S] [--shared-data]
//   NAME_fuzz_driver --iteration K --write-input FILE   # replay one input
//   NAME_fuzz_driver --write-seeds DIR                  # the corpus for libFuzzer
//   NAME_fuzz_driver FILE...                            # run these inputs (a libFuzzer finding)
//
// --shared-data adds the real snapshots of the shared data folder to the
// seeds, and exits with status 77 (ctest's skip) when the folder is absent.
// A failing input is a crash, a sanitizer report or an uncaught exception;
// the driver then names the iteration that failed, to replay it. A seed made
// in code that the target refuses fails the run too (exit status 1).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <string_view>
#include <vector>


#include "tests/fuzz/fuzz_target.h"

// In a sanitized build, a sanitizer report ends the process; its death
// callback names the failing iteration first.
#if defined(__SANITIZE_ADDRESS__)
#define OCTOCOSM_FUZZ_DRIVER_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define OCTOCOSM_FUZZ_DRIVER_SANITIZED 1
#endif
#endif
#ifdef OCTOCOSM_FUZZ_DRIVER_SANITIZED
#include <sanitizer/common_interface_defs.h>
#endif

namespace octocosm::fuzz {
namespace {

constexpr int kSkipped = 77;

// What the failure reports name.
const char* g_program = "";
long long g_iteration = -1;  // -1 while the seeds run unmutated
std::uint64_t g_seed = 0;

long long g_iterations = 0;
const char* g_input_file = nullptr;  // set while inputs from files run

void ReportFailure() {
  if (g_input_file != nullptr) {
    std::fprintf(stderr, "fuzz driver: failed on %s\n", g_input_file);
  } else if (g_iteration >= g_iterations && g_iterations > 0) {
    std::fprintf(stderr, "fuzz driver: failed at exit (a leak?) after %lld mutants; find the input by running fewer (--iterations)\n",
                 g_iterations);
  } else if (g_iteration < 0) {
    std::fprintf(stderr, "fuzz driver: failed on a seed (write them with: %s --write-seeds DIR)\n", g_program);
  } else {
    std::fprintf(stderr, "fuzz driver: failed at iteration %lld; replay: %s --seed %llu --iteration %lld --write-input FILE\n",
                 g_iteration, g_program, static_cast<unsigned long long>(g_seed), g_iteration);
  }
}

[[noreturn]] void OnTerminate() {
  ReportFailure();
  if (std::exception_ptr current = std::current_exception()) {
    try {
      std::rethrow_exception(current);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "fuzz driver: uncaught exception: %s\n", e.what());
    } catch (...) {
      std::fprintf(stderr, "fuzz driver: uncaught exception of unknown type\n");
    }
  }
  std::abort();
}

class Mutator {
 public:
  Mutator(std::uint64_t seed, std::uint64_t iteration) : rng_(seed ^ (iteration * 0x9E3779B97F4A7C15ull)) {}

  std::string Mutate(const std::vector<Seed>& seeds) {
    std::string bytes = seeds[Below(seeds.size())].bytes;
    const std::size_t count = 1 + Below(4);
    for (std::size_t i = 0; i < count; ++i) MutateOnce(bytes, seeds);
    return bytes;
  }

 private:
  std::size_t Below(std::size_t n) { return n == 0 ? 0 : static_cast<std::size_t>(rng_() % n); }

  // An offset in [0, size): half the time within the first 512 bytes.
  std::size_t Offset(std::size_t size) {
    if (size == 0) return 0;
    return Below(2) == 0 ? Below(std::min<std::size_t>(size, 512)) : Below(size);
  }

  template <typename T>
  void Overwrite(std::string& bytes, T value) {
    if (bytes.size() < sizeof(T)) return;
    char raw[sizeof(T)];
    std::memcpy(raw, &value, sizeof(T));
    if (Below(2) == 0) std::reverse(raw, raw + sizeof(T));
    std::memcpy(&bytes[Offset(bytes.size() - sizeof(T) + 1)], raw, sizeof(T));
  }

  void MutateOnce(std::string& bytes, const std::vector<Seed>& seeds) {
    switch (Below(9)) {
      case 0:  // a byte replaced
        if (!bytes.empty()) bytes[Offset(bytes.size())] = static_cast<char>(Below(256));
        break;
      case 1:  // a bit flipped
        if (!bytes.empty()) bytes[Offset(bytes.size())] ^= static_cast<char>(1u << Below(8));
        break;
      case 2:  // truncated
        bytes.resize(Offset(bytes.size() + 1));
        break;
      case 3: {  // a range erased
        const std::size_t at = Offset(bytes.size());
        bytes.erase(at, Below(std::min<std::size_t>(bytes.size() - at, 64) + 1));
        break;
      }
      case 4: {  // a range duplicated in place
        const std::size_t at = Offset(bytes.size());
        bytes.insert(at, bytes.substr(at, Below(64) + 1));
        break;
      }
      case 5: {  // a piece of another seed written over this one or inserted
        const std::string& other = seeds[Below(seeds.size())].bytes;
        if (other.empty()) break;
        const std::size_t from = Offset(other.size());
        const std::string piece = other.substr(from, Below(256) + 1);
        const std::size_t at = Offset(bytes.size() + 1);
        if (Below(2) == 0) {
          bytes.insert(at, piece);
        } else {
          bytes.replace(at, piece.size(), piece);
        }
        break;
      }
      case 6: {  // an interesting 32-bit integer
        static constexpr std::uint32_t kValues[] = {0,          1,          0xFFFFFFFFu, 0x7FFFFFFFu, 0x80000000u,
                                                    0x7FFFFFFEu, 8,          256,         0xFFFF,      0x10000,
                                                    4096,       0xFFFFFFF8u};
        Overwrite(bytes, kValues[Below(std::size(kValues))]);
        break;
      }
      case 7: {  // an interesting 64-bit integer
        static constexpr std::uint64_t kValues[] = {0,
                                                    1,
                                                    ~std::uint64_t{0},
                                                    std::uint64_t{1} << 31,
                                                    std::uint64_t{1} << 32,
                                                    std::uint64_t{1} << 63,
                                                    (std::uint64_t{1} << 63) - 1,
                                                    std::uint64_t{1} << 40,
                                                    0xFFFFFFFFull};
        Overwrite(bytes, kValues[Below(std::size(kValues))]);
        break;
      }
      default: {  // an interesting float or double
        static constexpr double kValues[] = {0.0,
                                             -0.0,
                                             -1.0,
                                             1e308,
                                             -1e308,
                                             5e-324,
                                             std::numeric_limits<double>::quiet_NaN(),
                                             std::numeric_limits<double>::infinity(),
                                             -std::numeric_limits<double>::infinity(),
                                             3.4e38,
                                             1e-45};
        const double value = kValues[Below(std::size(kValues))];
        if (Below(2) == 0) {
          Overwrite(bytes, static_cast<float>(value));
        } else {
          Overwrite(bytes, value);
        }
        break;
      }
    }
  }

  std::mt19937_64 rng_;
};

void Run(const std::string& bytes) {
  LLVMFuzzerTestOneInput(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
}

int Usage() {
  std::fprintf(stderr,
               "usage: %s [--iterations N] [--seed S] [--shared-data]\n"
               "       %s [--seed S] [--shared-data] --iteration K --write-input FILE\n"
               "       %s [--shared-data] --write-seeds DIR\n"
               "       %s FILE...\n",
               g_program, g_program, g_program, g_program);
  return 2;
}

}  // namespace
}  // namespace octocosm::fuzz

int main(int argc, char** argv) {
  using namespace octocosm::fuzz;
  g_program = argv[0];
  long long iterations = 1000;
  long long only_iteration = -1;
  bool shared = false;
  std::string write_input, write_seeds;
  std::vector<std::string> input_files;
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    const bool has_value = i + 1 < argc;
    if (arg == "--iterations" && has_value) {
      iterations = std::atoll(argv[++i]);
    } else if (arg == "--seed" && has_value) {
      g_seed = std::strtoull(argv[++i], nullptr, 10);
    } else if (arg == "--iteration" && has_value) {
      only_iteration = std::atoll(argv[++i]);
    } else if (arg == "--write-input" && has_value) {
      write_input = argv[++i];
    } else if (arg == "--write-seeds" && has_value) {
      write_seeds = argv[++i];
    } else if (arg == "--shared-data") {
      shared = true;
    } else if (!arg.starts_with("-")) {
      input_files.emplace_back(arg);
    } else {
      return Usage();
    }
  }
  std::string shared_data;
  if (shared) {
#ifdef OCTOCOSM_SHARED_DATA
    shared_data = OCTOCOSM_SHARED_DATA;
#endif
    if (shared_data.empty() || !std::filesystem::is_directory(shared_data)) {
      std::printf("no shared data folder at %s: skipped\n", shared_data.c_str());
      return kSkipped;
    }
  }
  std::set_terminate(OnTerminate);
#ifdef OCTOCOSM_FUZZ_DRIVER_SANITIZED
  __sanitizer_set_death_callback(ReportFailure);
#endif
  if (!input_files.empty()) {
    for (const std::string& file : input_files) {
      g_input_file = file.c_str();
      Run(ReadFileString(file));
    }
    std::printf("%zu inputs, no fault\n", input_files.size());
    return 0;
  }

  const std::vector<Seed> seeds = Seeds(shared_data);
  if (!write_seeds.empty()) {
    std::filesystem::create_directories(write_seeds);
    for (const Seed& seed : seeds) {
      std::ofstream(std::filesystem::path(write_seeds) / seed.name, std::ios::binary) << seed.bytes;
    }
    std::printf("%zu seeds written to %s\n", seeds.size(), write_seeds.c_str());
    return 0;
  }
  if (only_iteration >= 0) {
    const std::string input = Mutator(g_seed, static_cast<std::uint64_t>(only_iteration)).Mutate(seeds);
    if (!write_input.empty()) std::ofstream(write_input, std::ios::binary) << input;
    g_iteration = only_iteration;
    Run(input);
    std::printf("iteration %lld: %zu bytes, no fault\n", only_iteration, input.size());
    return 0;
  }
  g_iterations = iterations;
  for (const Seed& seed : seeds) {
    const std::size_t refusals = RefusalCount();
    Run(seed.bytes);
    // The real snapshots include files read alone that belong to a set.
    if (RefusalCount() != refusals && !shared) {
      std::fprintf(stderr, "fuzz driver: the target refused its seed %s (OCTOCOSM_FUZZ_PRINT_ERRORS=1 says why)\n",
                   seed.name.c_str());
      return 1;
    }
  }
  for (g_iteration = 0; g_iteration < iterations; ++g_iteration) {
    Run(Mutator(g_seed, static_cast<std::uint64_t>(g_iteration)).Mutate(seeds));
  }
  std::printf("%zu seeds and %lld mutants, no fault\n", seeds.size(), iterations);
  return 0;
}
