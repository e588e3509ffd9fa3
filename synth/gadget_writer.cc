#include "synth/gadget_writer.h"

#include <fcntl.h>
#include <unistd.h>

#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>

#include "base/error.h"
#include "storage/coding.h"

namespace octocosm::synth {
namespace {

void PutI32(std::uint8_t* out, std::int32_t value) { PutU32(out, static_cast<std::uint32_t>(value)); }

// A payload of floats or integers encoded little endian into `out`.
void EncodeFloats(std::span<const float> values, std::vector<std::uint8_t>& out) {
  out.resize(values.size() * 4);
  for (std::size_t i = 0; i < values.size(); ++i) PutU32(&out[4 * i], std::bit_cast<std::uint32_t>(values[i]));
}

constexpr std::uint64_t kMaxRecordBytes = std::numeric_limits<std::int32_t>::max();

}  // namespace

std::array<std::uint8_t, kGadgetHeaderSize> EncodeGadgetHeader(const GadgetHeader& header) {
  std::array<std::uint8_t, kGadgetHeaderSize> out{};
  std::uint8_t* p = out.data();
  for (int t = 0; t < 6; ++t) {
    PutU32(p + kHeaderNpartOffset + 4 * t, header.npart[t]);
    PutF64(p + kHeaderMassOffset + 8 * t, header.mass[t]);
    PutU32(p + kHeaderNpartTotalOffset + 4 * t, static_cast<std::uint32_t>(header.npart_total[t] & 0xffffffffu));
    PutU32(p + kHeaderNpartTotalHighOffset + 4 * t, static_cast<std::uint32_t>(header.npart_total[t] >> 32));
  }
  PutF64(p + kHeaderTimeOffset, header.time);
  PutF64(p + kHeaderRedshiftOffset, header.redshift);
  PutI32(p + kHeaderFlagSfrOffset, header.flag_sfr);
  PutI32(p + kHeaderFlagFeedbackOffset, header.flag_feedback);
  PutI32(p + kHeaderFlagCoolingOffset, header.flag_cooling);
  PutI32(p + kHeaderNumFilesOffset, header.num_files);
  PutF64(p + kHeaderBoxSizeOffset, header.box_size);
  PutF64(p + kHeaderOmega0Offset, header.omega0);
  PutF64(p + kHeaderOmegaLambdaOffset, header.omega_lambda);
  PutF64(p + kHeaderHubbleParamOffset, header.hubble_param);
  PutI32(p + kHeaderFlagStellarAgeOffset, header.flag_stellarage);
  PutI32(p + kHeaderFlagMetalsOffset, header.flag_metals);
  PutI32(p + kHeaderFlagEntropyOffset, header.flag_entropy_instead_u);
  return out;
}

float PositionToFloat(double position, float box) {
  float value = static_cast<float>(position);
  if (value >= box) value = std::nextafter(box, 0.0f);
  if (value < 0.0f) value = 0.0f;
  return value;
}

GadgetFileWriter::GadgetFileWriter(std::string path, const GadgetHeader& header, GadgetFormat format,
                                   int id_bytes)
    : path_(std::move(path)), temp_path_(path_ + ".tmp"), id_bytes_(id_bytes) {
  if (id_bytes != 4 && id_bytes != 8) throw Error::InvalidArgument(path_ + ": GADGET IDs must be 4 or 8 bytes");
  expected_ = 0;
  for (int t = 0; t < 6; ++t) {
    expected_ += header.npart[t];
    if (header.npart[t] > 0 && !(header.mass[t] > 0.0)) {
      throw Error::InvalidArgument(path_ + ": type " + std::to_string(t) +
                                   " has particles but no mass-table entry; per-particle masses are not supported");
    }
  }
  const std::uint64_t vector_bytes = 12 * expected_;
  const std::uint64_t id_payload_bytes = static_cast<std::uint64_t>(id_bytes) * expected_;
  if (vector_bytes > kMaxRecordBytes - 8) {
    throw Error::InvalidArgument(path_ + ": " + std::to_string(expected_) +
                                 " particles overflow a GADGET record's int32 byte count; use more files");
  }

  remove_on_interrupt_.emplace([temp_path = temp_path_] { ::unlink(temp_path.c_str()); });
  fd_ = ::open(temp_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw IoErrorFromErrno(temp_path_, "open", errno);

  // Every marker and name record is known now; only payloads come later.
  std::uint64_t offset = 0;
  auto write_record_frame = [&](const char* name, std::uint64_t payload_bytes) -> std::uint64_t {
    std::uint8_t frame[20];
    std::size_t used = 0;
    if (format == GadgetFormat::kFormat2) {
      PutU32(frame, 8);
      std::memcpy(frame + 4, name, 4);
      PutU32(frame + 8, static_cast<std::uint32_t>(payload_bytes + 8));
      PutU32(frame + 12, 8);
      used = 16;
    }
    PutU32(frame + used, static_cast<std::uint32_t>(payload_bytes));
    used += 4;
    WriteAt(offset, frame, used);
    const std::uint64_t payload = offset + used;
    std::uint8_t trailer[4];
    PutU32(trailer, static_cast<std::uint32_t>(payload_bytes));
    WriteAt(payload + payload_bytes, trailer, 4);
    offset = payload + payload_bytes + 4;
    return payload;
  };
  const std::uint64_t header_payload = write_record_frame("HEAD", kGadgetHeaderSize);
  const auto encoded = EncodeGadgetHeader(header);
  WriteAt(header_payload, encoded.data(), encoded.size());
  position_payload_ = write_record_frame("POS ", vector_bytes);
  velocity_payload_ = write_record_frame("VEL ", vector_bytes);
  id_payload_ = write_record_frame("ID  ", id_payload_bytes);
}

GadgetFileWriter::~GadgetFileWriter() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_) ::unlink(temp_path_.c_str());
}

void GadgetFileWriter::WriteAt(std::uint64_t offset, const void* data, std::size_t size) {
  const auto* bytes = static_cast<const std::uint8_t*>(data);
  while (size > 0) {
    const ssize_t done = ::pwrite(fd_, bytes, size, static_cast<off_t>(offset));
    if (done < 0) {
      if (errno == EINTR) continue;
      throw IoErrorFromErrno(temp_path_, "write", errno);
    }
    bytes += done;
    size -= static_cast<std::size_t>(done);
    offset += static_cast<std::uint64_t>(done);
  }
}

void GadgetFileWriter::Append(std::span<const float> positions, std::span<const float> velocities,
                              std::span<const std::uint64_t> ids) {
  const std::size_t count = ids.size();
  if (positions.size() != 3 * count || velocities.size() != 3 * count) {
    throw Error::InvalidArgument(path_ + ": Append needs 3 position and 3 velocity values per ID");
  }
  if (closed_) throw Error::InvalidArgument(path_ + ": Append after Close");
  if (count > expected_ - written_) {
    throw Error::InvalidArgument(path_ + ": more particles than the " + std::to_string(expected_) +
                                 " the header announces");
  }
  std::vector<std::uint8_t> buffer;
  EncodeFloats(positions, buffer);
  WriteAt(position_payload_ + 12 * written_, buffer.data(), buffer.size());
  EncodeFloats(velocities, buffer);
  WriteAt(velocity_payload_ + 12 * written_, buffer.data(), buffer.size());
  buffer.resize(count * static_cast<std::size_t>(id_bytes_));
  for (std::size_t i = 0; i < count; ++i) {
    if (id_bytes_ == 4) {
      if (ids[i] > std::numeric_limits<std::uint32_t>::max()) {
        throw Error::InvalidArgument(path_ + ": ID " + std::to_string(ids[i]) + " does not fit 32-bit IDs");
      }
      PutU32(&buffer[4 * i], static_cast<std::uint32_t>(ids[i]));
    } else {
      PutU64(&buffer[8 * i], ids[i]);
    }
  }
  WriteAt(id_payload_ + static_cast<std::uint64_t>(id_bytes_) * written_, buffer.data(), buffer.size());
  written_ += count;
}

void GadgetFileWriter::Close() {
  if (closed_) return;
  if (written_ != expected_) {
    throw Error::InvalidArgument(path_ + ": closed after " + std::to_string(written_) + " of " +
                                 std::to_string(expected_) + " particles");
  }
  if (::fsync(fd_) != 0) throw IoErrorFromErrno(temp_path_, "fsync", errno);
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) throw IoErrorFromErrno(temp_path_, "close", errno);
  closed_ = true;
}

void GadgetFileWriter::Commit() {
  if (!closed_) throw Error::InvalidArgument(path_ + ": Commit before Close");
  if (committed_) return;
  if (std::rename(temp_path_.c_str(), path_.c_str()) != 0) throw IoErrorFromErrno(path_, "rename", errno);
  committed_ = true;
  remove_on_interrupt_.reset();
}

GadgetSnapshotWriter::GadgetSnapshotWriter(std::string base, const GadgetSnapshotInfo& info, GadgetFormat format)
    : base_(std::move(base)), info_(info), format_(format) {
  if (info.particle_count == 0) throw Error::InvalidArgument(base_ + ": a snapshot needs at least one particle");
  if (info.num_files < 1 || static_cast<std::uint64_t>(info.num_files) > info.particle_count) {
    throw Error::InvalidArgument(base_ + ": number of files must be between 1 and the particle count, got " +
                                 std::to_string(info.num_files));
  }
  if (info.particle_type < 0 || info.particle_type > 5) {
    throw Error::InvalidArgument(base_ + ": GADGET particle type must be 0..5");
  }
  if (!(info.particle_mass > 0.0)) throw Error::InvalidArgument(base_ + ": particle mass must be positive");
  id_bytes_ = info.particle_count < (std::uint64_t{1} << 32) ? 4 : 8;
  for (int f = 0; f < info.num_files; ++f) {
    paths_.push_back(info.num_files == 1 ? base_ : base_ + "." + std::to_string(f));
  }
  OpenFile(0);
}

GadgetSnapshotWriter::~GadgetSnapshotWriter() = default;

void GadgetSnapshotWriter::OpenFile(int index) {
  const std::uint64_t count = info_.particle_count;
  const std::uint64_t files = static_cast<std::uint64_t>(info_.num_files);
  const std::uint64_t first = count * static_cast<std::uint64_t>(index) / files;
  const std::uint64_t last = count * static_cast<std::uint64_t>(index + 1) / files;
  if (last - first > std::numeric_limits<std::uint32_t>::max()) {
    throw Error::InvalidArgument(paths_[index] + ": more than 2^32 particles in one file; use more files");
  }
  GadgetHeader header;
  header.npart[info_.particle_type] = static_cast<std::uint32_t>(last - first);
  header.mass[info_.particle_type] = info_.particle_mass;
  header.npart_total[info_.particle_type] = count;
  header.time = info_.time;
  header.redshift = info_.redshift;
  header.num_files = info_.num_files;
  header.box_size = info_.box_size;
  header.omega0 = info_.omega0;
  header.omega_lambda = info_.omega_lambda;
  header.hubble_param = info_.hubble_param;
  files_.push_back(std::make_unique<GadgetFileWriter>(paths_[index], header, format_, id_bytes_));
  current_ = index;
}

void GadgetSnapshotWriter::Append(std::span<const float> positions, std::span<const float> velocities,
                                  std::span<const std::uint64_t> ids) {
  if (finished_) throw Error::InvalidArgument(base_ + ": Append after Finish");
  if (positions.size() != 3 * ids.size() || velocities.size() != 3 * ids.size()) {
    throw Error::InvalidArgument(base_ + ": Append needs 3 position and 3 velocity values per ID");
  }
  // Checked up front so that a rejected chunk writes nothing.
  if (ids.size() > info_.particle_count - written_) {
    throw Error::InvalidArgument(base_ + ": more particles than the " + std::to_string(info_.particle_count) +
                                 " announced");
  }
  written_ += ids.size();
  std::size_t done = 0;
  while (done < ids.size()) {
    GadgetFileWriter* file = files_.back().get();
    if (file->written() == file->expected()) {
      file->Close();
      OpenFile(current_ + 1);
      continue;
    }
    const std::size_t take =
        static_cast<std::size_t>(std::min<std::uint64_t>(ids.size() - done, file->expected() - file->written()));
    file->Append(positions.subspan(3 * done, 3 * take), velocities.subspan(3 * done, 3 * take),
                 ids.subspan(done, take));
    done += take;
  }
}

void GadgetSnapshotWriter::Finish() {
  if (finished_) return;
  if (written_ != info_.particle_count) {
    throw Error::InvalidArgument(base_ + ": finished after " + std::to_string(written_) + " of " +
                                 std::to_string(info_.particle_count) + " particles");
  }
  for (auto& file : files_) file->Close();
  for (auto& file : files_) file->Commit();
  finished_ = true;
}

}  // namespace octocosm::synth
