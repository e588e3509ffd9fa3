// The structure of one GADGET binary snapshot file (format 1 or 2).
//
// A GADGET file is a sequence of Fortran records: [int32 n][n bytes][int32 n].
// The first record is the 256-byte header; then come POS (3 x N reals), VEL
// (3 x N reals), ID (N integers), MASS (one real per particle of the types
// whose mass-table entry is 0) and code-specific blocks (U, RHO, ...).
// Format 2 puts a 16-byte record [int32 8]["NAME"][int32 n + 8][int32 8]
// before every block, so blocks are found by name; format 1 by position.
// The byte order is whatever the writing machine used: the first marker is
// 256 (format 1) or 8 (format 2), which tells both apart from their
// byte-swapped forms.
//
// ReadGadgetStructure() walks every record marker (reading 4 to 16 bytes per
// block, never the payloads) and checks that the markers agree, so that a
// truncated or spliced file is rejected before any particle is read.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "ingest/snapshot/binary_file.h"

namespace octocosm {

inline constexpr int kGadgetTypes = 6;

// The 256-byte GADGET-2 header (io_header in GADGET-2's allvars.h).
struct GadgetHeader {
  std::array<std::int32_t, kGadgetTypes> npart{};              // particles in this file, per type
  std::array<double, kGadgetTypes> mass_table{};               // 0 = masses in the MASS block
  double time = 0;                                             // scale factor when cosmological
  double redshift = 0;
  std::int32_t flag_sfr = 0, flag_feedback = 0;
  std::array<std::uint32_t, kGadgetTypes> npart_total{};       // low words of the totals
  std::int32_t flag_cooling = 0, num_files = 0;
  double box_size = 0, omega0 = 0, omega_lambda = 0, hubble_param = 0;
  std::int32_t flag_stellarage = 0, flag_metals = 0;
  std::array<std::uint32_t, kGadgetTypes> npart_total_high{};  // high words of the totals
  std::int32_t flag_entropy_instead_u = 0;

  std::uint64_t ParticleCount() const;    // sum of npart
  std::uint64_t MassBlockCount() const;   // particles whose mass is in the MASS block
};

struct GadgetBlock {
  std::string name;                 // "POS", "VEL", ...; format 1: by position, or "#k"
  std::uint64_t payload_offset = 0;
  std::uint64_t payload_bytes = 0;
};

struct GadgetFileStructure {
  int format = 1;     // 1 or 2
  bool swap = false;  // the file's byte order differs from this machine's
  GadgetHeader header;
  std::vector<GadgetBlock> blocks;  // every block after the header, in file order

  const GadgetBlock* Find(std::string_view name) const;
};

// Recognises the start of a GADGET file from its first 4 bytes.
struct GadgetSignature {
  int format;
  bool swap;
};
std::optional<GadgetSignature> SniffGadget(const std::uint8_t first_bytes[4]);

// Reads the header and the block table. Throws Error::BadInput naming the
// file and the record when the structure is broken.
GadgetFileStructure ReadGadgetStructure(const BinaryFile& file);

}  // namespace octocosm
