#include "ingest/snapshot/gadget_format.h"

#include <cstring>

#include "base/error.h"

namespace octocosm {
namespace {

constexpr std::uint32_t kHeaderBytes = 256;
constexpr std::uint32_t kNameRecordBytes = 8;

std::uint32_t ByteSwapped(std::uint32_t value) {
  return ((value & 0xffu) << 24) | ((value & 0xff00u) << 8) | ((value >> 8) & 0xff00u) | (value >> 24);
}

GadgetHeader DecodeHeader(const std::uint8_t* bytes, bool swap) {
  GadgetHeader header;
  auto i32 = [&](std::size_t offset) { return static_cast<std::int32_t>(LoadU32(bytes + offset, swap)); };
  auto u32 = [&](std::size_t offset) { return LoadU32(bytes + offset, swap); };
  auto f64 = [&](std::size_t offset) { return LoadF64(bytes + offset, swap); };
  for (int t = 0; t < kGadgetTypes; ++t) {
    header.npart[t] = i32(4 * t);
    header.mass_table[t] = f64(24 + 8 * t);
    header.npart_total[t] = u32(96 + 4 * t);
    header.npart_total_high[t] = u32(168 + 4 * t);
  }
  header.time = f64(72);
  header.redshift = f64(80);
  header.flag_sfr = i32(88);
  header.flag_feedback = i32(92);
  header.flag_cooling = i32(120);
  header.num_files = i32(124);
  header.box_size = f64(128);
  header.omega0 = f64(136);
  header.omega_lambda = f64(144);
  header.hubble_param = f64(152);
  header.flag_stellarage = i32(160);
  header.flag_metals = i32(164);
  header.flag_entropy_instead_u = i32(192);
  return header;
}

std::string NameFromRecord(const std::uint8_t* bytes) {
  std::string name(reinterpret_cast<const char*>(bytes), 4);
  while (!name.empty() && (name.back() == ' ' || name.back() == '\0')) name.pop_back();
  return name;
}

bool IsPrintableName(const std::string& name) {
  if (name.empty()) return false;
  for (char c : name) {
    if (c < 0x21 || c > 0x7e) return false;
  }
  return true;
}

}  // namespace

std::uint64_t GadgetHeader::ParticleCount() const {
  std::uint64_t sum = 0;
  for (std::int32_t n : npart) sum += static_cast<std::uint64_t>(n);
  return sum;
}

std::uint64_t GadgetHeader::MassBlockCount() const {
  std::uint64_t sum = 0;
  for (int t = 0; t < kGadgetTypes; ++t) {
    if (mass_table[t] == 0) sum += static_cast<std::uint64_t>(npart[t]);
  }
  return sum;
}

const GadgetBlock* GadgetFileStructure::Find(std::string_view name) const {
  for (const GadgetBlock& block : blocks) {
    if (block.name == name) return &block;
  }
  return nullptr;
}

std::optional<GadgetSignature> SniffGadget(const std::uint8_t first_bytes[4]) {
  std::uint32_t marker;
  std::memcpy(&marker, first_bytes, 4);
  // The marker is read in host order; a match with the swapped value means the
  // file was written on a machine of the other byte order.
  if (marker == kHeaderBytes) return GadgetSignature{1, false};
  if (marker == ByteSwapped(kHeaderBytes)) return GadgetSignature{1, true};
  if (marker == kNameRecordBytes) return GadgetSignature{2, false};
  if (marker == ByteSwapped(kNameRecordBytes)) return GadgetSignature{2, true};
  return std::nullopt;
}

GadgetFileStructure ReadGadgetStructure(const BinaryFile& file) {
  const std::string& path = file.path();
  std::uint8_t first[4];
  file.ReadAt(0, first, 4, "the first record marker");
  std::optional<GadgetSignature> signature = SniffGadget(first);
  if (!signature) {
    throw Error::BadInput(path, "not a GADGET file: the first record marker is neither 256 (format 1) nor 8 "
                                "(format 2) in either byte order");
  }
  GadgetFileStructure structure;
  structure.format = signature->format;
  structure.swap = signature->swap;

  std::uint64_t offset = 0;
  std::size_t record_number = 0;
  bool have_header = false;
  while (offset < file.size()) {
    std::string name;
    std::uint64_t declared_next = 0;
    std::string where;
    if (structure.format == 2) {
      std::uint8_t tag[16];
      file.ReadAt(offset, tag, sizeof tag, "the block-name record at offset " + std::to_string(offset));
      std::uint32_t begin = LoadU32(tag, structure.swap);
      std::uint32_t end = LoadU32(tag + 12, structure.swap);
      if (begin != kNameRecordBytes || end != kNameRecordBytes) {
        throw Error::BadInput(path, "block-name record at offset " + std::to_string(offset) + " has markers " +
                                        std::to_string(begin) + " and " + std::to_string(end) +
                                        "; expected 8 and 8 (format 2 puts one before every block)");
      }
      name = NameFromRecord(tag + 4);
      if (!IsPrintableName(name)) {
        throw Error::BadInput(path, "block-name record at offset " + std::to_string(offset) +
                                        " does not hold a printable block name");
      }
      declared_next = LoadU32(tag + 8, structure.swap);
      offset += sizeof tag;
      where = "block " + name;
    } else {
      static const char* const kFormat1Order[] = {"HEAD", "POS", "VEL", "ID"};
      if (record_number < 4) {
        name = kFormat1Order[record_number];
      } else if (record_number == 4 && structure.header.MassBlockCount() > 0) {
        name = "MASS";
      } else {
        name = "#" + std::to_string(record_number);
      }
      where = "block " + name + " (record " + std::to_string(record_number) + ")";
    }
    where += " at offset " + std::to_string(offset);

    std::uint8_t marker[4];
    file.ReadAt(offset, marker, 4, "the begin marker of " + where);
    std::uint64_t length = LoadU32(marker, structure.swap);
    if (length > file.size() - offset - 4 || file.size() - offset - 4 - length < 4) {
      throw Error::BadInput(path, "truncated: " + where + " declares " + std::to_string(length) +
                                      " bytes but the file ends at " + std::to_string(file.size()));
    }
    file.ReadAt(offset + 4 + length, marker, 4, "the end marker of " + where);
    std::uint64_t end_length = LoadU32(marker, structure.swap);
    if (end_length != length) {
      throw Error::BadInput(path, "record markers disagree in " + where + ": begin says " +
                                      std::to_string(length) + " bytes, end says " + std::to_string(end_length));
    }
    if (structure.format == 2 && declared_next != length + 8) {
      throw Error::BadInput(path, "the name record of " + where + " announces " + std::to_string(declared_next) +
                                      " bytes but the block record is " + std::to_string(length + 8) +
                                      " bytes with its markers");
    }
    if (!have_header) {
      if (name != "HEAD" || length != kHeaderBytes) {
        throw Error::BadInput(path, "the first block must be the 256-byte header HEAD; found " + name + " of " +
                                        std::to_string(length) + " bytes");
      }
      std::uint8_t bytes[kHeaderBytes];
      file.ReadAt(offset + 4, bytes, kHeaderBytes, "the header");
      structure.header = DecodeHeader(bytes, structure.swap);
      for (int t = 0; t < kGadgetTypes; ++t) {
        if (structure.header.npart[t] < 0) {
          throw Error::BadInput(path, "unreadable header: npart[" + std::to_string(t) + "] is negative (" +
                                          std::to_string(structure.header.npart[t]) + ")");
        }
      }
      have_header = true;
    } else {
      structure.blocks.push_back(GadgetBlock{name, offset + 4, length});
    }
    offset += 4 + length + 4;
    ++record_number;
  }
  if (!have_header) throw Error::BadInput(path, "empty file: no GADGET header");
  return structure;
}

}  // namespace octocosm
