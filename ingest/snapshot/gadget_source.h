// ParticleSource for GADGET binary snapshots (format 1 and 2, either byte
// order, single or multi-file). See gadget_format.h for the file structure and
// docs/INPUT_FORMATS.md for the quirks handled.
#pragma once

#include <memory>
#include <string>

#include "ingest/snapshot/snapshot_source.h"

namespace octocosm {

// `file` is any existing file of the snapshot; the others are found from its
// name and the header's num_files.
std::unique_ptr<ParticleSource> OpenGadgetSnapshot(const std::string& file, const ReadOptions& options);

}  // namespace octocosm
