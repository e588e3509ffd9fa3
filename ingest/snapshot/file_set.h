// Finding the files of a multi-file snapshot.
//
// GADGET and HDF5 snapshots that are written by many tasks at once are split
// into numbered files: snap.0, snap.1, ... or snap.0.hdf5, snap.1.hdf5, ...
// A user may name the set by its base name ("snap") or by any one of its
// files; the header of each file says how many files there are.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

namespace octocosm {

// "dir/snap.3.hdf5" -> stem "dir/snap", index 3, suffix ".hdf5". The number
// keeps its written width ("snap.007" -> width 3) when zero-padded.
struct NumberedName {
  std::string stem;
  std::size_t index = 0;
  std::size_t width = 1;
  std::string suffix;  // "", ".hdf5" or ".h5"

  std::string WithIndex(std::size_t other) const;
};

std::optional<NumberedName> ParseNumberedName(const std::string& path);

// Throws Error::NotFound when nothing is at `path`, and Error::BadInput
// saying what is there ("is a directory, not a snapshot file") when it is not
// a regular file: a directory, a device such as /dev/zero (endless bytes) or
// a FIFO (which cannot be read twice, and blocks an open until a writer
// comes) is never a snapshot.
void RequireRegularFile(const std::string& path);

// Returns `path` when it is an existing file, else the first existing of
// path.0, path.0.hdf5, path.0.h5, path.hdf5. Throws Error::NotFound naming
// every name tried, or, when nothing of those exists but `path` is a
// directory, device or FIFO, Error::BadInput saying so.
std::string LocateSnapshotFile(const std::string& path);

// Returns every file of the set that `file` belongs to, in order. `declared`
// is the file count its header declares; a count <= 0 (GADGET ICs often
// leave it 0) means: every consecutively numbered file that exists, or just
// `file` when it is not numbered. Throws Error::BadInput when the header
// declares several files but the name is not numbered, Error::NotFound when
// a declared file is missing, and Error::BadInput when one is not a regular
// file.
std::vector<std::string> ExpandFileSet(const std::string& file, long long declared);

}  // namespace octocosm
