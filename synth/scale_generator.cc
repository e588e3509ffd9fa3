#include "synth/scale_generator.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <system_error>

#include "base/error.h"
#include "base/mutex.h"
#include "base/parallel_for.h"
#include "synth/cosmic_web.h"
#include "synth/gadget_writer.h"
#include "synth/scale_sampler.h"

namespace octocosm::synth {
namespace {

constexpr int kDarkMatterType = 1;

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

ScaleResult RunScaleGenerator(const ScaleOptions& options, const std::function<void(const ScaleProgress&)>& progress) {
  ValidateScaleOptions(options);
  const auto start = std::chrono::steady_clock::now();

  const CosmicWeb web = BuildCosmicWeb(options);
  ScaleResult result;
  result.particle_count = options.particle_count;
  result.particle_mass = web.particle_mass;
  result.halos = web.halos.size();
  result.filaments = web.filaments.size();
  result.web_seconds = SecondsSince(start);

  const int file_count = ResolveScaleFileCount(options);
  const double length_scale = options.output_unit == LengthUnit::kKpcPerH ? 1000.0 : 1.0;
  const ScaleSampler sampler(web, options.seed, file_count, options.chunk_particles, length_scale);

  std::error_code error;
  std::filesystem::create_directories(options.output_directory, error);
  if (error) throw Error::Io(options.output_directory, "cannot create the output directory: " + error.message());
  const std::filesystem::path base = std::filesystem::path(options.output_directory) / options.snapshot_prefix;
  for (int f = 0; f < file_count; ++f) {
    result.files.push_back(file_count == 1 ? base.string() : base.string() + "." + std::to_string(f));
  }

  GadgetHeader header;
  header.mass[kDarkMatterType] = web.particle_mass;
  header.npart_total[kDarkMatterType] = options.particle_count;
  header.time = 1.0;
  header.redshift = 0.0;
  header.num_files = file_count;
  header.box_size = options.box_size_mpc_h * length_scale;
  header.omega0 = options.omega_matter;
  header.omega_lambda = options.omega_lambda;
  header.hubble_param = options.hubble;
  const int id_bytes = options.particle_count < (std::uint64_t{1} << 32) ? 4 : 8;

  // Closed files wait here, under their temporary names, for the final rename.
  std::vector<std::unique_ptr<GadgetFileWriter>> writers(static_cast<std::size_t>(file_count));
  std::atomic<int> next_file{0};
  Mutex mutex;  // guards the fields below and serialises progress calls
  int files_done = 0;
  std::uint64_t particles_done = 0;

  result.threads = std::min(ResolveThreadCount(options.threads), file_count);
  // On failure `writers` unlinks the temporary files.
  RunWorkers(result.threads, [&](int, const std::atomic<bool>& stop) {
    ScaleChunk chunk;
    for (int f = next_file++; f < file_count && !stop; f = next_file++) {
      GadgetHeader file_header = header;
      file_header.npart[kDarkMatterType] = static_cast<std::uint32_t>(sampler.FileParticleCount(f));
      auto writer = std::make_unique<GadgetFileWriter>(result.files[f], file_header, options.format, id_bytes);
      const std::uint64_t chunks = sampler.ChunkCount(f);
      for (std::uint64_t k = 0; k < chunks && !stop; ++k) {
        sampler.Fill(f, k, chunk);
        writer->Append(chunk.positions, chunk.velocities, chunk.ids);
      }
      if (stop) break;
      writer->Close();
      const std::uint64_t written = writer->written();
      writers[static_cast<std::size_t>(f)] = std::move(writer);
      MutexLock lock(mutex);
      ++files_done;
      particles_done += written;
      if (progress) {
        progress(ScaleProgress{f, files_done, file_count, particles_done, options.particle_count, SecondsSince(start),
                               result.files[f]});
      }
    }
  });

  for (auto& writer : writers) writer->Commit();
  result.total_seconds = SecondsSince(start);
  return result;
}

}  // namespace octocosm::synth
