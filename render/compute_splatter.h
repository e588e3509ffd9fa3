// The compute path of the splat pass (shaders/splat_comp.glsl): points read
// from their pools' column buffers by a compute shader, one invocation a
// point, and each blob added pixel by pixel into a float buffer with atomic
// adds, instead of being drawn as a point sprite. A GPU runs graphics on
// part of its multiprocessors only (data-centre GPUs on few of them) and
// spends a sprite's setup on blobs of one or two pixels; a compute dispatch
// reaches every multiprocessor. Blobs larger than the compute radius are
// listed and added after the dispatch by a workgroup each
// (shaders/splat_large_comp.glsl), its threads sharing the blob's pixels, so
// no blob is one thread's long loop and none passes through the graphics
// units. The image is the raster path's to float rounding: the same blobs
// (shaders/splat_point.glsl), the same pixels, the same weights, added in
// another order (and so not bit for bit the same from one run to the next).
//
// Needs GL_NV_shader_atomic_float (float atomic adds; NVIDIA's drivers and
// Mesa's llvmpipe have it) and 16 storage buffers in a compute shader
// (Supported()). Owned by SplatRenderer, which fills the Draws buffer and
// the frame's uniforms the shaders share with the raster path.
#pragma once

#include <cstdint>
#include <map>

#include "render/gl_objects.h"
#include "render/gpu_block_arena.h"

namespace octocosm {

// What the frame's points need beyond positions, weights, smoothing lengths
// and shapes: which further columns the compute shader reads.
struct ComputeColumns {
  bool velocity = false;    // velocity colour modes, Hermite interpolation
  bool dispersion = false;  // velocity colour modes
  bool type = false;        // colour by type
  bool id = false;          // highlighting the points of selected IDs
  bool links = false;       // interpolation: displacements
  bool hermite = false;     // Hermite interpolation: the neighbours' velocities
  bool cut = false;         // the cluster cut's entries (render/cluster_links.h)
};

class ComputeSplatter {
 public:
  // Whether the current context can run the compute path.
  static bool Supported();

  ComputeSplatter();
  ComputeSplatter(const ComputeSplatter&) = delete;
  ComputeSplatter& operator=(const ComputeSplatter&) = delete;

  // Sizes the accumulation for a target of width x height pixels (guard
  // margin included). False when one storage buffer cannot hold it: the
  // frame is then drawn by the raster path.
  bool Prepare(int width, int height);
  // Blobs above this radius (pixels) are added by a workgroup each.
  void set_compute_radius(double pixels) { compute_radius_ = static_cast<float>(pixels); }
  // Room for so many large blobs a dispatch (those past it are added by the
  // compute shader, more slowly). Tests shrink it.
  void set_large_blob_capacity(std::uint32_t blobs);

  // The most points of one pool a dispatch may span (from its first point to
  // its last), so that every column fits one storage-buffer binding; and the
  // alignment (points) of a dispatch's first point.
  std::uint32_t max_span_points() const { return max_span_points_; }
  std::uint32_t base_alignment() const { return base_alignment_; }

  // Whether a program reading these columns binds no more storage buffers
  // than a compute shader may (16 on some GPUs: with the cluster cut, every
  // optional column at once would need 17). Where not, the raster path draws
  // those points; both add into the same image.
  bool CanSplat(const ComputeColumns& columns) const;
  // Adds the points of draws [first_draw, first_draw + draw_count) of the
  // bound Draws buffer, all of `pool`, whose block.y/z/w give each draw's
  // first point in the pool, its count and the points before it in this
  // dispatch (`points` in all). The columns are bound from pool point `base`
  // (a multiple of base_alignment()) on. The caller has bound the frame's
  // uniforms (0), the selection (1), the blocks' parameters (3) and the
  // Draws (4). Leaves another program bound than it found.
  void Splat(const GpuBlockArena& arena, std::uint32_t pool, std::uint32_t first_draw, std::uint32_t draw_count,
             std::uint32_t points, std::uint32_t base, const ComputeColumns& columns);
  // Adds what the dispatches since the last Resolve accumulated into
  // `texture` (RGBA32F, the size given to Prepare) and clears it.
  void Resolve(GLuint texture);
  // Whether a dispatch has added anything since the last Resolve.
  bool pending() const { return pending_; }

 private:
  const GlProgram& ProgramFor(const ComputeColumns& columns);
  void SplatLargeBlobs();

  std::map<unsigned, GlProgram> programs_;  // by the columns read
  GlProgram large_program_;
  GlProgram resolve_;
  GlBuffer accumulation_;
  std::size_t accumulation_bytes_ = 0;
  GlBuffer large_blobs_;
  std::uint32_t large_capacity_ = 0;
  GlBuffer absent_column_;  // bound where a pool lacks a column the program declares
  int width_ = 0, height_ = 0;
  float compute_radius_ = 4;
  std::uint64_t max_block_bytes_ = 0;
  std::uint32_t max_span_points_ = 0;
  GLint max_storage_buffers_ = 16;
  std::uint32_t base_alignment_ = 256;
  bool pending_ = false;
};

}  // namespace octocosm
