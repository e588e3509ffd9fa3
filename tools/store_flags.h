// The store argument of every command that reads a store: a directory or an
// http(s) URL (docs/REMOTE.md), with --cache-dir and --cache-size, which keep
// the pages fetched from a server between runs.
#pragma once

#include <string>

namespace CLI {
class App;
}

namespace octocosm {

// Registers the positional `store` (into `store`), --cache-dir and
// --cache-size. Once the command line is parsed, the cache is opened and
// given to every HTTP file the command opens.
void AddStoreArgument(CLI::App& command, std::string& store);

}  // namespace octocosm
