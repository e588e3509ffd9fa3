#include "tools/store_flags.h"

#include <memory>

#include <CLI/CLI.hpp>

#include "storage/http_file.h"
#include "storage/range_cache.h"
#include "tools/cli_util.h"

namespace octocosm {

void AddStoreArgument(CLI::App& command, std::string& store) {
  struct CacheFlags {
    std::string directory;
    std::string size = "4G";
  };
  auto flags = std::make_shared<CacheFlags>();
  command.add_option("store", store, "store directory, or the URL of one on an HTTP(S) server (http://host/path)")
      ->required();
  command.add_option("--cache-dir", flags->directory,
                     "for a store URL: keep fetched pages in this directory between runs");
  command.add_option("--cache-size", flags->size, "--cache-dir's budget, e.g. 4G (least recently used out first)")
      ->default_val("4G");
  command.parse_complete_callback([flags] {
    if (flags->directory.empty()) return;
    HttpOptions options = DefaultHttpOptions();
    options.cache = RangeCache::Open(flags->directory, ParseByteSize(flags->size, "--cache-size"));
    SetDefaultHttpOptions(options);
  });
}

}  // namespace octocosm
