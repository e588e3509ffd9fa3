// A dataset store opened for use: the page-file store plus what the octree
// needs to interpret it (each epoch's cube, the node capacity, the depth
// limit), read from the manifest's dataset metadata written by ingest.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "index/cube.h"
#include "index/morton.h"
#include "storage/store_reader.h"

namespace octocosm {

class Dataset {
 public:
  // Opens the store at `directory`; throws Error (kCorruption when the
  // dataset metadata is missing or malformed, as StoreReader::Open otherwise).
  static Dataset Open(const std::string& directory);

  const StoreReader& store() const { return store_; }
  std::uint32_t epoch_count() const { return store_.epoch_count(); }
  const Cube& cube(std::uint32_t epoch) const { return cubes_.at(epoch); }
  std::uint64_t points(std::uint32_t epoch) const { return points_.at(epoch); }
  std::size_t capacity() const { return capacity_; }
  int max_level() const { return max_level_; }
  bool has_id_index() const { return !id_index_.empty(); }
  // The directory of the ID index store (empty when the dataset has no IDs).
  const std::string& id_index_directory() const { return id_index_; }
  // "file epoch N block rXXXX": how errors name a block.
  std::string Where(std::uint32_t epoch, NodeKey key) const;

 private:
  explicit Dataset(StoreReader store) : store_(std::move(store)) {}

  StoreReader store_;
  std::vector<Cube> cubes_;
  std::vector<std::uint64_t> points_;
  std::size_t capacity_ = 0;
  int max_level_ = kMaxLevel;
  std::string id_index_;
};

}  // namespace octocosm
