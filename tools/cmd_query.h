// `octocosm query` and `octocosm follow`: the parts the subcommands are made
// of, exposed so that tests can drive them without a process.
#pragma once

#include <cstdint>
#include <ostream>
#include <span>
#include <string>
#include <vector>

#include "index/dataset.h"

namespace octocosm {

// Reads an ID file: one non-negative integer per line; blank lines and lines
// starting with '#' are skipped, as is anything after a '#'. Throws
// Error::NotFound / Error::Io when the file cannot be read and
// Error::BadInput naming the file and line for anything else.
std::vector<std::uint64_t> ReadIdFile(const std::string& path);

struct FollowReport {
  std::uint64_t rows = 0;     // particle states written
  std::uint64_t missing = 0;  // (id, epoch) pairs not found, each noted
};

// Writes the trajectory of every ID as CSV rows id,epoch,time,x,y,z and, when
// the store holds velocities, vx,vy,vz; rows grouped by ID in the order
// given, epochs ascending. An ID missing from an epoch gets a line on `notes`
// (the first 100; then a count) and no row. Throws Error::NotFound when the
// store has no ID index.
FollowReport WriteTrajectories(const Dataset& dataset, std::span<const std::uint64_t> ids, std::ostream& csv,
                               std::ostream& notes);

}  // namespace octocosm
