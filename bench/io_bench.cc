// octocosm-bench-io: is octocosm IO-bound on this disk?
//
// For each page size (default 4 KiB, 64 KiB, 1 MiB) it writes a store of at
// least --size bytes of blocks (sizes drawn like octree nodes: 16 KiB to
// 640 KiB), then reads every block COLD (the page file dropped from the OS
// page cache with posix_fadvise(DONTNEED) before each pass):
//   raw-seq       the page file itself, front to back, in 8 MiB preads (the yardstick)
//   key           every block in key order (= file order), one thread
//   random        every block in random order, one thread
//   key+pool      key order through the BlockCache and a Prefetcher pool
//   random+pool   random order through the BlockCache and a Prefetcher pool
// and prints MB/s of block payload for each, with the ratio to raw-seq.
// Targets: key >= 0.8 x raw-seq; random+pool >= 0.5 x raw-seq.
//
// Run it on the disk you will store data on:  octocosm-bench-io --dir /data/tmp
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "base/error.h"
#include "storage/block_cache.h"
#include "storage/prefetcher.h"
#include "storage/store_reader.h"
#include "storage/store_writer.h"
#include "tools/cli_util.h"

namespace octocosm {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

struct Options {
  std::string dir = "octocosm-io-bench";
  std::string size = "2G";
  std::string page_sizes = "4K,64K,1M";
  std::string min_block = "16K", max_block = "640K";
  std::size_t workers = 4;
  std::string cache = "256M";
  std::uint64_t seed = 1;
  bool keep = false;
};

struct Pass {
  std::string name;
  double seconds = 0;
  std::uint64_t bytes = 0;
  double MBps() const { return seconds > 0 ? static_cast<double>(bytes) / seconds / 1e6 : 0; }
};

// Fills a buffer with cheap pseudo-random bytes (incompressible, so no layer
// below can cheat).
void FillRandom(Bytes& bytes, std::uint64_t& state) {
  std::size_t i = 0;
  for (; i + 8 <= bytes.size(); i += 8) {
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    for (int b = 0; b < 8; ++b) bytes[i + static_cast<std::size_t>(b)] = static_cast<std::uint8_t>(state >> (8 * b));
  }
  for (; i < bytes.size(); ++i) bytes[i] = static_cast<std::uint8_t>(state >> (i % 8));
}

Pass WriteStore(const std::string& dir, std::uint32_t page_size, const Options& o, std::vector<std::uint64_t>& keys) {
  const std::uint64_t target = ParseByteSize(o.size, "--size");
  const std::uint64_t lo = ParseByteSize(o.min_block, "--min-block"), hi = ParseByteSize(o.max_block, "--max-block");
  if (lo == 0 || hi < lo) throw Error::InvalidArgument("--min-block must be > 0 and <= --max-block");
  std::mt19937_64 rng(o.seed);
  std::uniform_int_distribution<std::uint64_t> size(lo, hi);
  std::uint64_t state = o.seed * 0x9e3779b97f4a7c15ull + 1;
  StoreWriterOptions options;
  options.page_size = page_size;
  const auto start = Clock::now();
  StoreWriter writer(dir, {{"benchmark", "octocosm-bench-io"}}, nlohmann::json::object(), options);
  writer.BeginEpoch(0, 0);
  Bytes block;
  std::uint64_t payload = 0;
  keys.clear();
  for (std::uint64_t key = 1; payload < target; ++key) {
    block.resize(size(rng));
    FillRandom(block, state);
    writer.AddBlock(key, block, block.size() / 32);
    keys.push_back(key);
    payload += block.size();
  }
  writer.EndEpoch();
  writer.Finish();
  return {"write", Seconds(start), payload};
}

Pass ReadRaw(const StoreReader& store) {
  store.DropCaches();
  const PageFileReader& file = store.page_file(0);
  (void)file;
  const std::string path = (fs::path(store.directory()) / store.epochs()[0].file).string();
  RandomAccessFile raw = RandomAccessFile::Open(path);
  raw.AdviseSequential();
  std::vector<std::uint8_t> buffer(8u << 20);
  const auto start = Clock::now();
  std::uint64_t offset = 0;
  for (;;) {
    const std::size_t got = raw.ReadAt(offset, buffer);
    if (got == 0) break;
    offset += got;
  }
  return {"raw-seq", Seconds(start), offset};
}

Pass ReadDirect(const StoreReader& store, const std::vector<std::uint64_t>& order, const char* name, bool sequential) {
  store.DropCaches();
  if (sequential) store.AdviseSequential();
  std::vector<std::uint8_t> buffer;
  std::uint64_t bytes = 0;
  const auto start = Clock::now();
  for (std::uint64_t key : order) {
    const auto entry = store.Lookup({0, key});
    if (!entry) throw Error::NotFound("benchmark block " + std::to_string(key));
    buffer.resize(entry->byte_length);
    bytes += store.ReadBlockInto({0, key}, buffer);
  }
  return {name, Seconds(start), bytes};
}

Pass ReadPooled(const StoreReader& store, const std::vector<std::uint64_t>& order, const char* name, bool sequential,
                const Options& o) {
  store.DropCaches();
  if (sequential) store.AdviseSequential();
  BlockCache cache(&store, ParseByteSize(o.cache, "--cache"));
  std::vector<BlockId> wanted;
  wanted.reserve(order.size());
  for (std::uint64_t key : order) wanted.push_back({0, key});
  const auto start = Clock::now();
  {
    Prefetcher::Options options;
    options.workers = o.workers;
    Prefetcher prefetcher(cache, options);
    prefetcher.Submit(wanted);
    prefetcher.Drain();
    const PrefetchStats stats = prefetcher.Stats();
    if (stats.failed > 0) throw Error::Io(store.directory(), std::to_string(stats.failed) + " prefetches failed");
  }
  return {name, Seconds(start), cache.Stats().bytes_read};
}

int Run(const Options& o) {
  std::vector<std::uint32_t> page_sizes;
  for (double p : ParseNumberList([&] {
         std::string s;  // "4K,64K" -> bytes list
         std::size_t begin = 0;
         while (begin <= o.page_sizes.size()) {
           const std::size_t end = std::min(o.page_sizes.find(',', begin), o.page_sizes.size());
           if (!s.empty()) s += ",";
           s += std::to_string(ParseByteSize(o.page_sizes.substr(begin, end - begin), "--page-sizes"));
           begin = end + 1;
         }
         return s;
       }(), "--page-sizes")) {
    page_sizes.push_back(static_cast<std::uint32_t>(p));
  }
  std::printf("octocosm-bench-io: store of >= %s per page size in %s, blocks %s..%s, pool of %zu workers, cache %s\n",
              o.size.c_str(), fs::absolute(o.dir).c_str(), o.min_block.c_str(), o.max_block.c_str(), o.workers,
              o.cache.c_str());
  std::printf("%-9s %-12s %10s %10s %8s %12s\n", "page", "pass", "MB/s", "seconds", "ratio", "file MB");
  for (std::uint32_t page_size : page_sizes) {
    const std::string dir = (fs::path(o.dir) / ("store-" + std::to_string(page_size))).string();
    fs::remove_all(dir);
    std::vector<std::uint64_t> keys;
    const Pass write = WriteStore(dir, page_size, o, keys);
    const StoreReader store = StoreReader::Open(dir);
    const double file_mb = static_cast<double>(store.epochs()[0].file_size) / 1e6;
    std::vector<std::uint64_t> shuffled = keys;
    std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937_64(o.seed));

    const Pass raw = ReadRaw(store);
    const std::vector<Pass> passes = {
        write,
        raw,
        ReadDirect(store, keys, "key", true),
        ReadDirect(store, shuffled, "random", false),
        ReadPooled(store, keys, "key+pool", true, o),
        ReadPooled(store, shuffled, "random+pool", false, o),
    };
    const std::string page = HumanBytes(page_size);
    for (const Pass& pass : passes) {
      std::printf("%-9s %-12s %10.1f %10.2f %8.2f %12.1f\n", page.c_str(), pass.name.c_str(), pass.MBps(), pass.seconds,
                  raw.MBps() > 0 ? pass.MBps() / raw.MBps() : 0.0, file_mb);
    }
    std::printf("%-9s payload %.1f MB in %zu blocks; the page file is %.1f MB (%.1f%% padding)\n", page.c_str(),
                static_cast<double>(write.bytes) / 1e6, keys.size(), file_mb,
                100.0 * (1.0 - static_cast<double>(write.bytes) / 1e6 / file_mb));
    std::fflush(stdout);
    if (!o.keep) fs::remove_all(dir);
  }
  if (!o.keep) fs::remove_all(o.dir);
  std::printf("ratio = MB/s of block payload / MB/s of the raw sequential read of the same file, both cold.\n"
              "targets: key >= 0.80, random+pool >= 0.50\n");
  return 0;
}

}  // namespace
}  // namespace octocosm

int main(int argc, char** argv) {
  octocosm::Options o;
  CLI::App app{"octocosm-bench-io: cold block-read throughput of the page store against raw sequential reads"};
  app.add_option("--dir", o.dir, "scratch directory on the disk to measure (removed afterwards)")->default_val(o.dir);
  app.add_option("--size", o.size, "payload bytes per store (at least 2G for a meaningful figure)")->default_val(o.size);
  app.add_option("--page-sizes", o.page_sizes, "page sizes to compare")->default_val(o.page_sizes);
  app.add_option("--min-block", o.min_block, "smallest block")->default_val(o.min_block);
  app.add_option("--max-block", o.max_block, "largest block")->default_val(o.max_block);
  app.add_option("--workers", o.workers, "prefetch pool threads")->default_val(o.workers)->check(CLI::Range(1, 256));
  app.add_option("--cache", o.cache, "block cache budget for the pooled passes")->default_val(o.cache);
  app.add_option("--seed", o.seed, "block sizes and random order")->default_val(o.seed);
  app.add_flag("--keep", o.keep, "keep the stores");
  CLI11_PARSE(app, argc, argv);
  try {
    return octocosm::Run(o);
  } catch (const octocosm::Error& e) {
    std::fprintf(stderr, "octocosm-bench-io: %s\n", e.what());
    return 1;
  }
}
