#include "storage/manifest.h"

#include <cinttypes>
#include <cstdio>

#include "base/error.h"
#include "storage/checksum.h"
#include "storage/page_file_format.h"

namespace octocosm {
namespace {

std::string HexDigits16(std::uint64_t id) {
  char text[17];
  std::snprintf(text, sizeof text, "%016" PRIx64, id);
  return text;
}

// Pulls typed members out of a JSON object, with errors that name the file
// and the member's place ("epochs[2].block_count").
class ManifestFields {
 public:
  ManifestFields(const nlohmann::json& object, std::string path, std::string where)
      : object_(object), path_(std::move(path)), where_(std::move(where)) {
    if (!object_.is_object()) throw Bad(where_.empty() ? "the manifest is not a JSON object" : where_ + " is not an object");
  }

  const nlohmann::json& Member(const char* name) const {
    auto found = object_.find(name);
    if (found == object_.end()) throw Bad("missing member \"" + Name(name) + "\"");
    return *found;
  }

  std::uint64_t Unsigned(const char* name, std::uint64_t max) const {
    const nlohmann::json& value = Member(name);
    if (!value.is_number_unsigned() || value.get<std::uint64_t>() > max) {
      throw Bad("\"" + Name(name) + "\" must be an integer in [0, " + std::to_string(max) + "], got " + value.dump());
    }
    return value.get<std::uint64_t>();
  }

  double Number(const char* name) const {
    const nlohmann::json& value = Member(name);
    if (!value.is_number()) throw Bad("\"" + Name(name) + "\" must be a number, got " + value.dump());
    return value.get<double>();
  }

  std::string String(const char* name) const {
    const nlohmann::json& value = Member(name);
    if (!value.is_string()) throw Bad("\"" + Name(name) + "\" must be a string, got " + value.dump());
    return value.get<std::string>();
  }

  Error Bad(const std::string& what) const { return Error::Corruption(path_, "bad manifest: " + what); }

 private:
  std::string Name(const char* name) const { return where_.empty() ? name : where_ + "." + name; }

  const nlohmann::json& object_;
  std::string path_;
  std::string where_;
};

bool IsPlainFileName(const std::string& name) {
  return !name.empty() && name != "." && name != ".." && name.find('/') == std::string::npos &&
         name.find('\0') == std::string::npos;
}

// XXH3-64 of the manifest's canonical text without its checksum member.
std::uint64_t ManifestChecksum(nlohmann::json manifest) {
  manifest.erase(kManifestChecksumMember);
  const std::string text = manifest.dump();
  return Checksum64({reinterpret_cast<const std::uint8_t*>(text.data()), text.size()});
}

}  // namespace

void SealManifest(nlohmann::json& manifest) {
  manifest[kManifestChecksumMember] = HexDigits16(ManifestChecksum(manifest));
}

std::string EpochFileName(std::uint32_t epoch) {
  char name[32];
  std::snprintf(name, sizeof name, "epoch-%05u.pages", epoch);
  return name;
}

nlohmann::json Manifest::ToJson() const {
  nlohmann::json epoch_list = nlohmann::json::array();
  for (const EpochInfo& info : epochs) {
    epoch_list.push_back({{"epoch", info.epoch},
                          {"file", info.file},
                          {"time", info.time},
                          {"redshift", info.redshift},
                          {"block_count", info.block_count},
                          {"file_size", info.file_size}});
  }
  nlohmann::json json = {{"format", kStoreFormatName},
                         {"format_version", kStoreFormatVersion},
                         {"store_id", HexDigits16(store_id)},
                         {"page_size", page_size},
                         {"dataset", dataset},
                         {"attribute_schema", attribute_schema},
                         {"epochs", std::move(epoch_list)}};
  SealManifest(json);
  return json;
}

Manifest Manifest::FromJson(const nlohmann::json& json, const std::string& path) {
  ManifestFields fields(json, path, "");
  if (fields.String("format") != kStoreFormatName) {
    throw fields.Bad("\"format\" is " + fields.Member("format").dump() + ", expected \"" + kStoreFormatName + "\"");
  }
  const nlohmann::json& version = fields.Member("format_version");
  if (!version.is_number_integer()) throw fields.Bad("\"format_version\" must be an integer");
  if (version.get<std::int64_t>() != kStoreFormatVersion) {
    throw Error::NotSupported(path, "store format version " + version.dump() + "; this build reads version " +
                                        std::to_string(kStoreFormatVersion));
  }
  // After the version, whose layout may differ, and before any other member
  // is believed.
  const std::string stored_checksum = fields.String(kManifestChecksumMember);
  const std::uint64_t computed_checksum = ManifestChecksum(json);
  if (stored_checksum != HexDigits16(computed_checksum)) {
    throw fields.Bad("checksum mismatch: stored \"" + stored_checksum + "\", computed \"" +
                     HexDigits16(computed_checksum) + "\" (the manifest was changed after it was written)");
  }
  Manifest manifest;
  std::string id_text = fields.String("store_id");
  if (id_text.size() != 16 || id_text.find_first_not_of("0123456789abcdef") != std::string::npos) {
    throw fields.Bad("\"store_id\" must be 16 lowercase hex digits, got \"" + id_text + "\"");
  }
  manifest.store_id = std::stoull(id_text, nullptr, 16);
  std::uint64_t page_size = fields.Unsigned("page_size", kMaxPageSize);
  if (!IsValidPageSize(page_size)) {
    throw fields.Bad("\"page_size\" " + std::to_string(page_size) + " is not a power of two in [4096, 16777216]");
  }
  manifest.page_size = static_cast<std::uint32_t>(page_size);
  manifest.dataset = fields.Member("dataset");
  if (!manifest.dataset.is_object()) throw fields.Bad("\"dataset\" must be an object");
  manifest.attribute_schema = fields.Member("attribute_schema");
  const nlohmann::json& epochs = fields.Member("epochs");
  if (!epochs.is_array()) throw fields.Bad("\"epochs\" must be an array");
  for (std::size_t i = 0; i < epochs.size(); ++i) {
    ManifestFields epoch(epochs[i], path, "epochs[" + std::to_string(i) + "]");
    EpochInfo info;
    info.epoch = static_cast<std::uint32_t>(epoch.Unsigned("epoch", UINT32_MAX));
    if (info.epoch != i) {
      throw epoch.Bad("epochs[" + std::to_string(i) + "] has \"epoch\" " + std::to_string(info.epoch) +
                      "; epochs must be numbered 0, 1, 2, ... in order");
    }
    info.file = epoch.String("file");
    if (!IsPlainFileName(info.file)) {
      throw epoch.Bad("epochs[" + std::to_string(i) + "].file \"" + info.file +
                      "\" is not a plain file name inside the store directory");
    }
    info.time = epoch.Number("time");
    info.redshift = epoch.Number("redshift");
    info.block_count = epoch.Unsigned("block_count", UINT64_MAX);
    info.file_size = epoch.Unsigned("file_size", UINT64_MAX);
    manifest.epochs.push_back(std::move(info));
  }
  return manifest;
}

Manifest Manifest::Parse(std::string_view text, const std::string& path) {
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& error) {
    // A syntax error, or a number beyond a double's range (1e400).
    throw Error::Corruption(path, std::string("bad manifest: not valid JSON: ") + error.what());
  }
  return FromJson(json, path);
}

}  // namespace octocosm
