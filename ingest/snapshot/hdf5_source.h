// ParticleSource for HDF5 snapshots in the GADGET layout (GADGET-2/3/4, AREPO)
// and SWIFT's variant of it: /Header attributes and one /PartTypeN group per
// particle type holding Coordinates, Velocities, ParticleIDs and Masses, and
// for gas (PartType0) SmoothingLength (GADGET-4, AREPO) or SmoothingLengths
// (SWIFT, whose h is converted to the radius of the kernel's support).
// Datasets are read chunk by chunk with hyperslab selections, converted by
// HDF5 to the chunk's column types, so float and double files read alike.
// Opening one starts a reader process that makes every libhdf5 call on the
// files, walking their structure and then reading the particles the source
// asks for (ReadOptions::isolate_hdf5), so that libhdf5 crashing on a
// damaged file is an Error naming it (docs/INPUT_FORMATS.md).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

// True when `bytes` (the first 8 bytes of a file) are the HDF5 signature.
bool IsHdf5Signature(const std::uint8_t bytes[8]);

// `file` is any existing file of the snapshot; the others are found from its
// name and the header's NumFilesPerSnapshot.
std::unique_ptr<ParticleSource> OpenHdf5Snapshot(const std::string& file, const ReadOptions& options);

}  // namespace octocosm
