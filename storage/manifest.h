// The store manifest, manifest.json (docs/FORMAT.md section 1.2): which page
// files make up the store, the store id they must all carry, and the caller's
// dataset metadata and attribute schema, kept as opaque JSON. The manifest
// carries a checksum of everything else in it: a reader relies on the
// caller's metadata (a cube origin, an epoch's time) as much as on a block,
// and no other check would notice a flipped bit there.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace octocosm {

inline constexpr char kManifestFileName[] = "manifest.json";
inline constexpr char kStoreFormatName[] = "octocosm-store";
inline constexpr int kStoreFormatVersion = 2;
inline constexpr char kManifestChecksumMember[] = "checksum";
inline constexpr char kTemporarySuffix[] = ".tmp";

struct EpochInfo {
  std::uint32_t epoch = 0;
  std::string file;  // page file name inside the store directory
  double time = 0;
  double redshift = 0;
  std::uint64_t block_count = 0;
  std::uint64_t file_size = 0;
};

struct Manifest {
  std::uint64_t store_id = 0;
  std::uint32_t page_size = 0;
  nlohmann::json dataset = nlohmann::json::object();
  nlohmann::json attribute_schema;
  std::vector<EpochInfo> epochs;

  // With its checksum (SealManifest).
  nlohmann::json ToJson() const;
  // Checks the checksum and every member (docs/FORMAT.md 1.2) and throws
  // kCorruption (or kNotSupported for an unknown format version) naming `path`.
  static Manifest FromJson(const nlohmann::json& json, const std::string& path);
  static Manifest Parse(std::string_view text, const std::string& path);
};

// Sets `manifest`'s checksum member to the XXH3-64 (16 lowercase hex
// digits) of its compact serialization without that member: keys sorted,
// numbers in their shortest round-trip form, so the same JSON value gives the
// same text whatever the file's layout.
void SealManifest(nlohmann::json& manifest);

// "epoch-00007.pages"
std::string EpochFileName(std::uint32_t epoch);

}  // namespace octocosm
