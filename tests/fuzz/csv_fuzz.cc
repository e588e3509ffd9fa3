// Fuzz target: the CSV reader (ingest/snapshot/csv_source.h), with the
// delimiter detected from the header row.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "tests/fuzz/fuzz_target.h"
#include "tests/fuzz/snapshot_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  octocosm::ReadOptions options;
  options.format = "csv";
  octocosm::fuzz::ReadSnapshotBytes(data, size, "points.csv", options);
  return 0;
}

namespace octocosm::fuzz {

std::vector<Seed> Seeds(const std::string&) {
  return {
      {"comma.csv", "x,y,z,vx,vy,vz,mass,id\n0.5,1.5,2.5,1,2,3,0.25,7\n-1e3,2E-2,3,0,0,0,1,8\n4,5,6,-1,-2,-3,2,9\n"},
      {"whitespace.csv", "# positions only\nX Y\tZ\n\n1 2 3\n4\t5 6\r\n7 8 9\n"},
      {"quoted.csv", "\"id\",\"z\",\"y\",\"x\",extra\n1,0.1,0.2,0.3,hello\n2,0.4,0.5,0.6,world\n"},
      {"mass.csv", "x,y,z,mass\n1,1,1,0.5\n2,2,2,1.5\n"},
  };
}

}  // namespace octocosm::fuzz
