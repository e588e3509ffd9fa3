#include "index/block_codec.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "base/error.h"
#include "index/extended_sum.h"
#include "index/nth_largest.h"
#include "storage/checksum.h"
#include "storage/coding.h"

namespace octocosm {
namespace {

std::uint64_t Checksum(const std::uint8_t* data, std::size_t size) { return Checksum64({data, size}); }

// Column ids run from 1 to the number of columns.
constexpr std::uint8_t kMaxColumnId = static_cast<std::uint8_t>(kColumnIds.size());

bool IsRequired(ColumnId id) {
  return id == ColumnId::kPosition || id == ColumnId::kWeight || id == ColumnId::kSmoothing || id == ColumnId::kType;
}

std::uint64_t BytesPerPoint(ColumnId id, std::uint8_t encoding) {
  switch (id) {
    case ColumnId::kPosition: return 6;
    case ColumnId::kWeight: return 4;
    case ColumnId::kSmoothing: return 2;
    case ColumnId::kVelocity: return 6;
    case ColumnId::kId: return encoding == kEncodingIdOffsets ? 4 : 8;
    case ColumnId::kType: return 1;
    case ColumnId::kDisplacement:
    case ColumnId::kNextVelocity:
    case ColumnId::kPrevDisplacement:
    case ColumnId::kPrevVelocity: return 6;
    case ColumnId::kVelocityDispersion: return 2;
    case ColumnId::kShape: return 6;
    case ColumnId::kChildCluster: return 0;  // its entries are the children's points (ColumnLength)
    case ColumnId::kRefineBound: return 6;
  }
  return 0;
}

std::uint64_t ChildClusterEntryBytes(std::uint8_t encoding) { return encoding == kEncodingChildClusterU32 ? 4 : 2; }

// A column's length in bytes for n points: the child_cluster column's
// follows its entry count (below 2^40, so that no product overflows).
std::uint64_t ColumnLength(ColumnId id, std::uint8_t encoding, std::uint64_t n, std::uint64_t child_cluster_entries) {
  if (id == ColumnId::kChildCluster) {
    return child_cluster_entries < (std::uint64_t{1} << 40) ? ChildClusterEntryBytes(encoding) * child_cluster_entries
                                                            : UINT64_MAX;
  }
  return BytesPerPoint(id, encoding) * n;
}

std::string ColumnWhat(ColumnId id, const std::string& what) {
  return std::string("column '") + ColumnName(id) + "': " + what;
}

// ---- Encoding ---------------------------------------------------------------

void CheckLength(const char* name, std::size_t actual, std::size_t expected) {
  if (actual != expected) {
    throw Error::InvalidArgument(std::string("EncodeBlock: column ") + name + " has " + std::to_string(actual) +
                                 " values, expected " + std::to_string(expected));
  }
}

// The point's grid coordinates at `bits` (its kept grid point, or placed from its position).
std::array<std::uint64_t, 3> PointGrid(const NodePoints& points, std::size_t i, const Cube& cube, int bits) {
  if (points.grid.empty()) return cube.GridCoords(&points.position[3 * i], bits);
  return {GridAxisAt(points.grid[i], 0, bits), GridAxisAt(points.grid[i], 1, bits), GridAxisAt(points.grid[i], 2, bits)};
}

// Throws for the first point that lies outside the node or in another octant
// than octant_offsets put it in; EncodePositions found one.
[[noreturn, gnu::cold]] void ThrowForMisplacedPoint(const NodePoints& points, NodeKey key, const Cube& cube) {
  const int bits = key.level() + 16;
  const CellCoord cell = key.cell();
  const std::array<std::uint64_t, 3> node = {cell.x, cell.y, cell.z};
  for (int octant = 0; octant < 8; ++octant) {
    for (std::size_t i = points.octant_offsets[octant]; i < points.octant_offsets[octant + 1]; ++i) {
      const auto g = PointGrid(points, i, cube, bits);
      const double* p = &points.position[3 * i];
      int point_octant = 0;
      for (int a = 0; a < 3; ++a) {
        if ((g[a] >> 16) != node[a]) {
          throw Error::InvalidArgument("EncodeBlock: point " + std::to_string(i) + " (" + std::to_string(p[0]) + ", " +
                                       std::to_string(p[1]) + ", " + std::to_string(p[2]) + ") lies outside node " +
                                       key.Path());
        }
        point_octant |= static_cast<int>((g[a] >> 15) & 1) << a;
      }
      if (point_octant != octant) {
        throw Error::InvalidArgument("EncodeBlock: point " + std::to_string(i) + " of node " + key.Path() +
                                     " lies in child octant " + std::to_string(point_octant) +
                                     " but octant_offsets put it in octant " + std::to_string(octant) +
                                     " (use OrderByOctant)");
      }
    }
  }
  throw std::logic_error("EncodeBlock: no misplaced point in node " + key.Path());
}

// Each point's 16-bit position inside the node. Every point is checked (inside
// the node, in the octant octant_offsets put it in) without a branch per
// point; only a failed check goes back to find the point and say what is wrong.
void EncodePositions(const NodePoints& points, NodeKey key, const Cube& cube, std::uint8_t* out) {
  const int bits = key.level() + 16;
  const CellCoord cell = key.cell();
  const std::array<std::uint64_t, 3> base = {std::uint64_t{cell.x} << 16, std::uint64_t{cell.y} << 16,
                                             std::uint64_t{cell.z} << 16};
  // Everything the loop reads is held in locals: the output is written as
  // bytes, which may alias anything, so members would be loaded again after
  // every store.
  std::uint64_t misplaced = 0;
  const auto encode = [out, base, offsets = points.octant_offsets, &misplaced](auto grid_of) {
    std::uint64_t found = 0;
    for (int octant = 0; octant < 8; ++octant) {
      const std::uint64_t ox = octant & 1, oy = (octant >> 1) & 1, oz = (octant >> 2) & 1;
      const std::size_t end = offsets[octant + 1];
      for (std::size_t i = offsets[octant]; i < end; ++i) {
        const std::array<std::uint64_t, 3> g = grid_of(i);
        // Below 2^16 inside the node (and wrapped past it below the node), so
        // q >> 15 is the octant's bit exactly when the point is where it belongs.
        const std::uint64_t qx = g[0] - base[0], qy = g[1] - base[1], qz = g[2] - base[2];
        found |= ((qx >> 15) ^ ox) | ((qy >> 15) ^ oy) | ((qz >> 15) ^ oz);
        PutU16(out + 6 * i, static_cast<std::uint16_t>(qx));
        PutU16(out + 6 * i + 2, static_cast<std::uint16_t>(qy));
        PutU16(out + 6 * i + 4, static_cast<std::uint16_t>(qz));
      }
    }
    misplaced = found;
  };
  if (points.grid.empty()) {
    encode([&cube, bits, position = points.position.data()](std::size_t i) {
      return cube.GridCoords(position + 3 * i, bits);
    });
  } else {
    encode([shift = kFinestGridBits - bits, grid = points.grid.data()](std::size_t i) {
      return std::array<std::uint64_t, 3>{grid[i][0] >> shift, grid[i][1] >> shift, grid[i][2] >> shift};
    });
  }
  if (misplaced != 0) ThrowForMisplacedPoint(points, key, cube);
}

// Largest-remainder apportionment of K units in proportion to the weights:
// each point gets floor(K * w / W) units, and the units left over go one each
// to the points with the largest fractional parts, so the units sum to K
// exactly. Returns the unit (W / K).
double EncodeWeights(const std::vector<double>& weight, std::uint8_t* out) {
  const std::size_t n = weight.size();
  if (n == 0) return 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(weight[i]) || weight[i] < 0) {
      throw Error::InvalidArgument("EncodeBlock: weight " + std::to_string(i) + " is " + std::to_string(weight[i]) +
                                   ", must be finite and >= 0");
    }
  }
  const long double total = ExtendedSum(weight);
  if (!(total > 0) || !std::isfinite(static_cast<double>(total))) {
    throw Error::InvalidArgument("EncodeBlock: the weights sum to " + std::to_string(static_cast<double>(total)) +
                                 ", must be finite and > 0");
  }
  const long double k = static_cast<long double>(kWeightTotalUnits);
  if (std::all_of(weight.begin(), weight.end(), [&](double w) { return w == weight.front(); })) {
    // Equal weights (a leaf of equal-mass particles, the usual case) share one
    // ideal, so one floor and one remainder: the leftover units go to the
    // lowest indices, as the tie rule below would give them, without a
    // division and a selection per point.
    const long double ideal = std::min(k, weight.front() / total * k);
    const auto whole = static_cast<std::uint64_t>(std::floor(ideal));
    const std::int64_t deficit =
        static_cast<std::int64_t>(kWeightTotalUnits) - static_cast<std::int64_t>(whole * n);
    if (deficit >= 0 && static_cast<std::size_t>(deficit) < n) {
      for (std::size_t i = 0; i < n; ++i) {
        PutU32(out + 4 * i, static_cast<std::uint32_t>(whole + (i < static_cast<std::size_t>(deficit) ? 1 : 0)));
      }
      return static_cast<double>(total / k);
    }
  }
  std::vector<std::uint64_t> units(n);
  std::vector<double> remainder(n);
  std::int64_t assigned = 0;
  // Per point in double, not long double: the units still sum to K exactly
  // (the deficit below settles that), and x87 code per point (a control-word
  // switch and a store and reload for every floor) made EncodeBlock twice as
  // slow in one build of the program.
  const double units_per_weight = static_cast<double>(k / total);
  const double max_units = static_cast<double>(kWeightTotalUnits);
  for (std::size_t i = 0; i < n; ++i) {
    const double ideal = std::min(max_units, weight[i] * units_per_weight);
    units[i] = static_cast<std::uint64_t>(ideal);  // floor: ideal >= 0
    remainder[i] = ideal - static_cast<double>(units[i]);
    assigned += static_cast<std::int64_t>(units[i]);
  }
  std::int64_t deficit = static_cast<std::int64_t>(kWeightTotalUnits) - assigned;
  if (deficit > 0 && static_cast<std::size_t>(deficit) < n) {
    // The usual case: a unit more for each of the `deficit` largest
    // remainders, ties to the lower index. Selecting the threshold among the
    // remainders themselves, not through an index order, keeps the selection
    // a pass over contiguous doubles.
    const double threshold = NthLargest(remainder, static_cast<std::size_t>(deficit - 1));
    std::int64_t above = 0;
    for (std::size_t i = 0; i < n; ++i) above += remainder[i] > threshold ? 1 : 0;
    // Without a branch on the remainder, which is random: the branch was
    // mispredicted that often. The ties, rare, get their units after.
    for (std::size_t i = 0; i < n; ++i) units[i] += remainder[i] > threshold ? 1 : 0;
    std::int64_t ties = deficit - above;  // at least 1: the threshold itself
    for (std::size_t i = 0; i < n && ties > 0; ++i) {
      if (remainder[i] == threshold) {
        ++units[i];
        --ties;
      }
    }
  } else if (deficit != 0) {
    // Ties go to the lower index, so the result does not depend on the sort.
    std::vector<std::uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    const auto larger_remainder = [&](std::uint32_t a, std::uint32_t b) {
      return remainder[a] != remainder[b] ? remainder[a] > remainder[b] : a < b;
    };
    std::sort(order.begin(), order.end(), larger_remainder);
    // Rounding can leave the floors a unit or so above K as well as below.
    for (std::size_t j = 0; deficit > 0; j = (j + 1) % n, --deficit) ++units[order[j]];
    for (std::size_t j = n - 1; deficit < 0; j = (j + n - 1) % n) {
      if (units[order[j]] > 0) {
        --units[order[j]];
        ++deficit;
      }
    }
  }
  for (std::size_t i = 0; i < n; ++i) PutU32(out + 4 * i, static_cast<std::uint32_t>(units[i]));
  return static_cast<double>(total / k);
}

// std::round (half away from zero), without the libm call it is on baseline
// x86-64 (no SSE4.1): truncation, then the fraction (exact for |x| < 2^52)
// decides; std::round elsewhere, NaN and infinities included.
double Round(double x) {
  if (!(std::fabs(x) < 0x1p52)) return std::round(x);
  const double whole = static_cast<double>(static_cast<std::int64_t>(x));
  const double fraction = x - whole;
  if (fraction >= 0.5) return whole + 1;
  if (fraction <= -0.5) return whole - 1;
  return whole;
}

// The nearest 16-bit code to x (halves up) for 0 <= x < 65536 and a hair
// past it, without a branch: the fraction is random in quantized data, so a
// branch on it was mispredicted half the time. The clamp is an integer one.
std::uint16_t NearestCode(double x) {
  const std::int32_t whole = static_cast<std::int32_t>(x);
  const std::int32_t code = whole + static_cast<std::int32_t>(x - static_cast<double>(whole) >= 0.5);
  return static_cast<std::uint16_t>(std::min(code, std::int32_t{65535}));
}

std::uint16_t SmoothingCode(double h, double node_size) {
  const double code = Round((std::log2(h / node_size) - kSmoothingLog2Min) * kSmoothingPerOctave);
  if (code >= 65535) return 65535;
  if (code > 0) return static_cast<std::uint16_t>(code);  // also false for -inf (h == 0)
  return 0;
}

#if defined(__SSE2__)
// NearestCode((v[i] - offset[i % 12]) * scale[i % 12]) for the first `whole`
// values (a multiple of 12), written as little-endian 16-bit codes: the same
// truncation, comparison with a half and clamp, two values to an
// instruction. GCC 12 leaves the scalar loop unvectorized, and it was a
// quarter of EncodeBlock's time.
void EncodeRangedLanes(const float* v, std::size_t whole, const std::array<double, 12>& offset,
                       const std::array<double, 12>& scale, std::uint8_t* out) {
  __m128d offset2[6], scale2[6];
  for (std::size_t p = 0; p < 6; ++p) {
    offset2[p] = _mm_loadu_pd(&offset[2 * p]);
    scale2[p] = _mm_loadu_pd(&scale[2 * p]);
  }
  const __m128d half = _mm_set1_pd(0.5);
  const __m128i last_code = _mm_set1_epi32(65535);
  const __m128i bias32 = _mm_set1_epi32(32768);
  const __m128i bias16 = _mm_set1_epi16(static_cast<short>(0x8000));
  // Two doubles' codes, as int32 in the low half.
  const auto codes2 = [&](__m128 floats, bool upper, std::size_t p) {
    const __m128d x = _mm_mul_pd(_mm_sub_pd(_mm_cvtps_pd(upper ? _mm_movehl_ps(floats, floats) : floats), offset2[p]),
                                 scale2[p]);
    const __m128i truncated = _mm_cvttpd_epi32(x);
    const __m128d up = _mm_cmpge_pd(_mm_sub_pd(x, _mm_cvtepi32_pd(truncated)), half);
    // The comparison's 64-bit masks to the low two 32-bit lanes; a mask is -1.
    const __m128i up32 = _mm_shuffle_epi32(_mm_castpd_si128(up), _MM_SHUFFLE(3, 3, 2, 0));
    return _mm_sub_epi32(truncated, up32);
  };
  // Four codes as int32, clamped to 65535.
  const auto codes4 = [&](__m128 floats, std::size_t p) {
    const __m128i code = _mm_unpacklo_epi64(codes2(floats, false, p), codes2(floats, true, p + 1));
    const __m128i over = _mm_cmpgt_epi32(code, last_code);
    return _mm_or_si128(_mm_andnot_si128(over, code), _mm_and_si128(over, last_code));
  };
  // int32 codes in [0, 65535] to uint16: shifted into int16's range, packed
  // with signed saturation (which never bites), shifted back.
  const auto pack = [&](__m128i a, __m128i b) {
    return _mm_xor_si128(_mm_packs_epi32(_mm_sub_epi32(a, bias32), _mm_sub_epi32(b, bias32)), bias16);
  };
  for (std::size_t i = 0; i < whole; i += 12) {
    const __m128i c0 = codes4(_mm_loadu_ps(v + i), 0);
    const __m128i c1 = codes4(_mm_loadu_ps(v + i + 4), 2);
    const __m128i c2 = codes4(_mm_loadu_ps(v + i + 8), 4);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + 2 * i), pack(c0, c1));
    _mm_storel_epi64(reinterpret_cast<__m128i*>(out + 2 * i + 16), pack(c2, c2));
  }
}
#endif

void EncodeSmoothing(const std::vector<double>& smoothing, double node_size, std::uint8_t* out) {
  // A node's lengths repeat (one per density cell and weight,
  // index/sampler.h), so a small direct-mapped cache of (length, code) saves
  // most log2 calls. A slot is valid once its length is set: lengths are >= 0,
  // never the initial -1.
  constexpr std::size_t kSlots = 1024;
  std::array<double, kSlots> cached_length;
  std::array<std::uint16_t, kSlots> cached_code;
  cached_length.fill(-1.0);
  for (std::size_t i = 0; i < smoothing.size(); ++i) {
    const double h = smoothing[i];
    if (!std::isfinite(h) || h < 0) {
      throw Error::InvalidArgument("EncodeBlock: smoothing length " + std::to_string(i) + " is " + std::to_string(h) +
                                   ", must be finite and >= 0");
    }
    const std::uint64_t bits = std::bit_cast<std::uint64_t>(h);
    const std::size_t slot = static_cast<std::size_t>((bits ^ (bits >> 29) ^ (bits >> 41)) % kSlots);
    if (std::bit_cast<std::uint64_t>(cached_length[slot]) != bits) {
      cached_length[slot] = h;
      cached_code[slot] = SmoothingCode(h, node_size);
    }
    PutU16(out + 2 * i, cached_code[slot]);
  }
}

// Quantizes 3-vectors between per-component min and max; writes min, max to params.
void EncodeRanged3(const char* name, const std::vector<float>& values, std::uint8_t* out, std::uint8_t* params) {
  const std::size_t n = values.size() / 3;
  std::array<float, 3> lo{0, 0, 0}, hi{0, 0, 0};
  // The range and finiteness in twelve lanes (four points), which the
  // compiler keeps in vector registers: a loop that stopped at each value to
  // test it took a fifth of EncodeBlock's time. Lane j holds component j % 3.
  // x - x is 0 for a finite x and NaN otherwise, and NaN stays in a sum.
  constexpr std::size_t kLanes = 12;
  std::array<float, kLanes> lane_lo{}, lane_hi{}, lane_nonfinite{};
  if (n > 0) {
    for (std::size_t j = 0; j < kLanes; ++j) lane_lo[j] = lane_hi[j] = values[j % 3];
  }
  const float* v = values.data();
  const std::size_t whole = 3 * n / kLanes * kLanes;
#if defined(__SSE2__)
  // GCC 12 leaves this loop scalar; minps and maxps are the ternaries below
  // exactly (the second operand when either is NaN or both are equal).
  {
    __m128 lo4[3], hi4[3], nonfinite4[3];
    for (std::size_t r = 0; r < 3; ++r) {
      lo4[r] = _mm_loadu_ps(&lane_lo[4 * r]);
      hi4[r] = _mm_loadu_ps(&lane_hi[4 * r]);
      nonfinite4[r] = _mm_setzero_ps();
    }
    for (std::size_t i = 0; i < whole; i += kLanes) {
      for (std::size_t r = 0; r < 3; ++r) {
        const __m128 x = _mm_loadu_ps(v + i + 4 * r);
        lo4[r] = _mm_min_ps(x, lo4[r]);
        hi4[r] = _mm_max_ps(x, hi4[r]);
        nonfinite4[r] = _mm_add_ps(nonfinite4[r], _mm_sub_ps(x, x));
      }
    }
    for (std::size_t r = 0; r < 3; ++r) {
      _mm_storeu_ps(&lane_lo[4 * r], lo4[r]);
      _mm_storeu_ps(&lane_hi[4 * r], hi4[r]);
      _mm_storeu_ps(&lane_nonfinite[4 * r], nonfinite4[r]);
    }
  }
#else
  for (std::size_t i = 0; i < whole; i += kLanes) {
    for (std::size_t j = 0; j < kLanes; ++j) {
      const float x = v[i + j];
      lane_lo[j] = x < lane_lo[j] ? x : lane_lo[j];
      lane_hi[j] = lane_hi[j] < x ? x : lane_hi[j];
      lane_nonfinite[j] += x - x;
    }
  }
#endif
  for (std::size_t i = whole; i < 3 * n; ++i) {
    const float x = v[i];
    lane_lo[i % 3] = x < lane_lo[i % 3] ? x : lane_lo[i % 3];
    lane_hi[i % 3] = lane_hi[i % 3] < x ? x : lane_hi[i % 3];
    lane_nonfinite[i % 3] += x - x;
  }
  bool finite = true;
  for (std::size_t j = 0; j < kLanes; ++j) finite &= lane_nonfinite[j] == 0;
  if (!finite) {
    for (std::size_t i = 0; i < 3 * n; ++i) {
      if (!std::isfinite(v[i])) {
        throw Error::InvalidArgument(std::string("EncodeBlock: ") + name + " of point " + std::to_string(i / 3) +
                                     " is not finite");
      }
    }
  }
  for (int a = 0; a < 3; ++a) {
    lo[a] = lane_lo[a];
    hi[a] = lane_hi[a];
  }
  for (std::size_t j = 3; j < kLanes; ++j) {
    lo[j % 3] = std::min(lo[j % 3], lane_lo[j]);
    hi[j % 3] = std::max(hi[j % 3], lane_hi[j]);
  }
  for (int a = 0; a < 3; ++a) {
    PutF32(params + 4 * a, lo[a]);
    PutF32(params + 12 + 4 * a, hi[a]);
  }
  // Codes per unit of each component, multiplied rather than divided by the
  // range: a division per value was two fifths of EncodeBlock's time. The
  // product can round a hair past a half, off by at most that from the
  // nearest code. A constant component (range 0) codes as 0.
  std::array<double, 3> scale{};
  for (int a = 0; a < 3; ++a) {
    const double range = static_cast<double>(hi[a]) - lo[a];
    scale[a] = range > 0 ? 65535.0 / range : 0.0;
  }
  // In [0, 65535] up to rounding: values are finite and lo <= value <= hi.
  // Twelve lanes again, their codes gathered before they are stored.
  std::array<double, kLanes> lane_offset{}, lane_scale{};
  for (std::size_t j = 0; j < kLanes; ++j) {
    lane_offset[j] = lo[j % 3];
    lane_scale[j] = scale[j % 3];
  }
#if defined(__SSE2__)
  if constexpr (kHostIsLittleEndian) {
    EncodeRangedLanes(v, whole, lane_offset, lane_scale, out);
  } else
#endif
  {
    for (std::size_t i = 0; i < whole; i += kLanes) {
      std::array<std::uint16_t, kLanes> codes;
      for (std::size_t j = 0; j < kLanes; ++j) codes[j] = NearestCode((v[i + j] - lane_offset[j]) * lane_scale[j]);
      for (std::size_t j = 0; j < kLanes; ++j) PutU16(out + 2 * (i + j), codes[j]);
    }
  }
  for (std::size_t i = whole; i < 3 * n; ++i) PutU16(out + 2 * i, NearestCode((v[i] - lane_offset[i % 3]) * lane_scale[i % 3]));
}

// Quantizes scalars that must be finite and >= 0 (velocity dispersions)
// between their min and max; writes f32 min, f32 max to params. The range is
// taken in float, as stored, so every value lies in [min, max].
void EncodeNonNegativeRanged1(const char* name, const std::vector<float>& values, std::uint8_t* out,
                              std::uint8_t* params) {
  float lo = 0, hi = 0;
  for (std::size_t i = 0; i < values.size(); ++i) {
    const float x = values[i];
    if (!std::isfinite(x) || !(x >= 0)) {
      throw Error::InvalidArgument(std::string("EncodeBlock: ") + name + " of point " + std::to_string(i) + " is " +
                                   std::to_string(x) + ", must be finite and >= 0");
    }
    if (i == 0 || x < lo) lo = x;
    if (i == 0 || x > hi) hi = x;
  }
  // + 0.0f turns a -0 minimum into +0, so that a reader checking min >= 0
  // by the sign bit agrees.
  lo += 0.0f;
  PutF32(params, lo);
  PutF32(params + 4, hi);
  const double range = static_cast<double>(hi) - lo;
  const double scale = range > 0 ? 65535.0 / range : 0.0;  // a constant column codes as 0
  for (std::size_t i = 0; i < values.size(); ++i) PutU16(out + 2 * i, NearestCode((values[i] - double{lo}) * scale));
}

// Column 14's log2 codes: 256 to an octave, above a per-component base
// chosen so that every value of the block has a code.
constexpr double kRefineBoundCodesPerOctave = 256;
constexpr std::int32_t kRefineBoundLowestBase = -160;  // below the smallest float
constexpr std::int32_t kRefineBoundHighestBase = 128;

// 2^(j / 256) for j < 256: a code's value is one of them times a power of
// two, so that coding a value costs no exp2 call.
const std::array<double, 256>& OctaveSteps() {
  static const std::array<double, 256> steps = [] {
    std::array<double, 256> s{};
    for (int j = 0; j < 256; ++j) s[static_cast<std::size_t>(j)] = std::exp2(j / kRefineBoundCodesPerOctave);
    return s;
  }();
  return steps;
}

float RefineBoundValue(std::int32_t base, std::uint16_t code) {
  if (code == 0) return 0.0f;
  // 2^k built from its bits (k = base + code / 256 lies in [-160, 384): a
  // normal double), as ldexp would give it.
  const std::int64_t k = std::int64_t{base} + (code >> 8);
  const auto power = std::bit_cast<double>(static_cast<std::uint64_t>(k + 1023) << 52);
  return static_cast<float>(OctaveSteps()[code & 255] * power);
}

// The smallest code whose value is at least x (> 0), or 65535: unique, so
// that a value that is a code's (rounded to a float) comes back as that code.
std::uint16_t RefineBoundCode(std::int32_t base, float x) {
  // x = f 2^e with f in [1, 2): the first step at least f, in the octave of e.
  int e = 0;
  const double f = 2 * std::frexp(double{x}, &e);
  --e;
  const std::array<double, 256>& steps = OctaveSteps();
  auto j = static_cast<std::int64_t>(std::lower_bound(steps.begin(), steps.end(), f) - steps.begin());
  const std::int64_t exact = (std::int64_t{e} - base) * 256 + j;  // j == 256: the next octave's first
  auto c = static_cast<std::uint16_t>(std::clamp<std::int64_t>(exact, 1, 65535));
  // The step's value rounds to a float at least x; so may the one before it
  // (a value a float rounded up to x), which is then the smallest.
  while (c < 65535 && RefineBoundValue(base, c) < x) ++c;
  while (c > 1 && RefineBoundValue(base, c - 1) >= x) --c;
  // Past FLT_MAX (only for values within a code of it), the largest finite code.
  while (c > 1 && !std::isfinite(RefineBoundValue(base, c))) --c;
  return c;
}

// Per component, the base that gives the block's smallest positive value a
// code (an octave to spare below it), or, when the values span more octaves
// than the codes do, the base that gives its largest one (smaller values
// then round up).
std::array<std::int32_t, 3> RefineBoundBases(const std::vector<float>& bounds) {
  std::array<float, 3> lo{INFINITY, INFINITY, INFINITY}, hi{0, 0, 0};
  for (std::size_t i = 0; i < bounds.size(); ++i) {
    const float x = bounds[i];
    if (!std::isfinite(x) || !(x >= 0)) {
      throw Error::InvalidArgument("refine_bound of point " + std::to_string(i / 3) + " holds " + std::to_string(x) +
                                   ", must be finite and >= 0");
    }
    if (x > 0) {
      lo[i % 3] = std::min(lo[i % 3], x);
      hi[i % 3] = std::max(hi[i % 3], x);
    }
  }
  std::array<std::int32_t, 3> base{};
  for (int k = 0; k < 3; ++k) {
    if (!(hi[k] > 0)) continue;
    const auto low = static_cast<std::int32_t>(std::floor(std::log2(double{lo[k]}))) - 1;
    const auto high = static_cast<std::int32_t>(std::ceil(std::log2(double{hi[k]}))) + 1 - 65535 / 256;
    base[k] = std::clamp(std::max(low, high), kRefineBoundLowestBase, kRefineBoundHighestBase);
  }
  return base;
}

void EncodeRefineBounds(const std::vector<float>& bounds, std::uint8_t* out, std::uint8_t* params) {
  const std::array<std::int32_t, 3> base = RefineBoundBases(bounds);
  for (int k = 0; k < 3; ++k) PutU32(params + 4 * k, static_cast<std::uint32_t>(base[k]));
  for (std::size_t i = 0; i < bounds.size(); ++i) {
    PutU16(out + 2 * i, bounds[i] > 0 ? RefineBoundCode(base[i % 3], bounds[i]) : 0);
  }
}

// The child_cluster column's contract (index/block_codec.h): every entry a
// point of the node, every point named, octants non-decreasing.
template <typename Fail>
void CheckChildClusterEntries(std::span<const std::uint32_t> entries, std::uint32_t n,
                              const std::array<std::uint32_t, 9>& octant_offsets, Fail&& fail) {
  std::vector<bool> named(n, false);
  int octant = 0;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const std::uint32_t c = entries[i];
    if (c >= n) fail("entry " + std::to_string(i) + " names point " + std::to_string(c) + " of " + std::to_string(n));
    int at = octant;
    while (c >= octant_offsets[at + 1]) ++at;
    if (c < octant_offsets[at]) {
      fail("entry " + std::to_string(i) + " names a cluster in octant " + std::to_string(at) +
           " before one in octant " + std::to_string(octant));
    }
    octant = at;
    named[c] = true;
  }
  for (std::uint32_t c = 0; c < n; ++c) {
    if (!named[c]) fail("point " + std::to_string(c) + " holds none of the children's points");
  }
}

void CheckChildClusters(const NodePoints& points, NodeKey key) {
  if (points.size() > std::numeric_limits<std::uint32_t>::max()) return;  // refused by the caller
  CheckChildClusterEntries(points.child_cluster, static_cast<std::uint32_t>(points.size()), points.octant_offsets,
                           [&](const std::string& what) {
                             throw Error::InvalidArgument("EncodeBlock: column 'child_cluster' of node " + key.Path() +
                                                          ": " + what);
                           });
}

// ---- Decoding ---------------------------------------------------------------

void DecodeChildClusters(const BlockHeader& header, const BlockColumn& column, std::span<const std::uint8_t> bytes,
                         const std::string& where, std::vector<std::uint32_t>& out) {
  const std::size_t entries = bytes.size() / ChildClusterEntryBytes(column.encoding);
  out.resize(entries);
  for (std::size_t i = 0; i < entries; ++i) {
    out[i] = column.encoding == kEncodingChildClusterU32 ? GetU32(bytes.data() + 4 * i) : GetU16(bytes.data() + 2 * i);
  }
  CheckChildClusterEntries(out, header.point_count, header.octant_offsets,
                           [&](const std::string& what) { throw Error::Corruption(where, ColumnWhat(column.id, what)); });
}

void DecodeRanged3(const BlockColumn& column, std::uint32_t n, std::span<const std::uint8_t> bytes,
                   const std::string& where, std::vector<float>& out) {
  std::array<double, 3> lo{}, hi{}, step{};
  for (int a = 0; a < 3; ++a) {
    const float min = GetF32(column.params.data() + 4 * a);
    const float max = GetF32(column.params.data() + 12 + 4 * a);
    if (!std::isfinite(min) || !std::isfinite(max) || !(min <= max)) {
      throw Error::Corruption(where, ColumnWhat(column.id, "range of component " + std::to_string(a) + " is [" +
                                                               std::to_string(min) + ", " + std::to_string(max) +
                                                               "], expected finite min <= max"));
    }
    lo[a] = min;
    hi[a] = max;
    step[a] = (static_cast<double>(max) - min) / 65535.0;
  }
  out.resize(3 * std::size_t{n});
  for (std::size_t i = 0; i < 3 * std::size_t{n}; ++i) {
    // Clamped so that rounding near +-FLT_MAX cannot leave the float range.
    const double v = lo[i % 3] + GetU16(bytes.data() + 2 * i) * step[i % 3];
    out[i] = static_cast<float>(std::min(v, hi[i % 3]));
  }
}

// Shape codes (index/cluster_shape.h) as they are: an off-diagonal code of
// 255 is not one the encoder writes.
void EncodeShapes(const std::vector<std::uint8_t>& codes, std::uint8_t* out) {
  for (std::size_t i = 0; i < codes.size(); ++i) {
    if (i % 6 >= 3 && codes[i] > 254) {
      throw Error::InvalidArgument("EncodeBlock: column 'shape': off-diagonal code " + std::to_string(codes[i]) +
                                   " of point " + std::to_string(i / 6) + " is above 254");
    }
  }
  if (!codes.empty()) std::memcpy(out, codes.data(), codes.size());
}

void DecodeShapes(const BlockColumn& column, std::uint32_t n, std::span<const std::uint8_t> bytes,
                  const std::string& where, std::vector<std::uint8_t>& out) {
  out.assign(bytes.begin(), bytes.begin() + 6 * std::size_t{n});
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (i % 6 >= 3 && out[i] > 254) {
      throw Error::Corruption(where, ColumnWhat(column.id, "off-diagonal code 255 at point " + std::to_string(i / 6)));
    }
  }
}

// The inverse of EncodeNonNegativeRanged1, checking its parameters.
void DecodeNonNegativeRanged1(const BlockColumn& column, std::uint32_t n, std::span<const std::uint8_t> bytes,
                              const std::string& where, std::vector<float>& out) {
  const float min = GetF32(column.params.data());
  const float max = GetF32(column.params.data() + 4);
  if (!std::isfinite(min) || !std::isfinite(max) || !(min >= 0) || !(min <= max)) {
    throw Error::Corruption(where, ColumnWhat(column.id, "range is [" + std::to_string(min) + ", " +
                                                             std::to_string(max) + "], expected finite 0 <= min <= max"));
  }
  const double lo = min, hi = max;
  const double step = (hi - lo) / 65535.0;
  out.resize(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    // Clamped so that rounding near FLT_MAX cannot leave the float range.
    out[i] = static_cast<float>(std::min(lo + GetU16(bytes.data() + 2 * std::size_t{i}) * step, hi));
  }
}

}  // namespace

const char* ColumnName(ColumnId id) {
  switch (id) {
    case ColumnId::kPosition: return "position";
    case ColumnId::kWeight: return "weight";
    case ColumnId::kSmoothing: return "smoothing";
    case ColumnId::kVelocity: return "velocity";
    case ColumnId::kId: return "id";
    case ColumnId::kType: return "type";
    case ColumnId::kDisplacement: return "displacement";
    case ColumnId::kNextVelocity: return "next_velocity";
    case ColumnId::kPrevDisplacement: return "prev_displacement";
    case ColumnId::kPrevVelocity: return "prev_velocity";
    case ColumnId::kVelocityDispersion: return "velocity_dispersion";
    case ColumnId::kShape: return "shape";
    case ColumnId::kChildCluster: return "child_cluster";
    case ColumnId::kRefineBound: return "refine_bound";
  }
  return "unknown";
}

std::string ColumnNames(ColumnSet columns) {
  std::string names;
  for (const ColumnId id : kColumnIds) {
    if (columns & ColumnBit(id)) names += (names.empty() ? "" : ",") + std::string(ColumnName(id));
  }
  return names;
}

void QuantizeRefineBounds(std::vector<float>& bounds) {
  const std::array<std::int32_t, 3> base = RefineBoundBases(bounds);
  for (std::size_t i = 0; i < bounds.size(); ++i) {
    if (bounds[i] > 0) bounds[i] = RefineBoundValue(base[i % 3], RefineBoundCode(base[i % 3], bounds[i]));
  }
}

double StoredSmoothing(double h, double node_size) {
  return node_size * std::exp2(kSmoothingLog2Min + SmoothingCode(h, node_size) / double{kSmoothingPerOctave});
}

const BlockColumn* BlockHeader::Find(ColumnId id) const {
  for (const BlockColumn& c : columns) {
    if (c.id == id) return &c;
  }
  return nullptr;
}

Bytes EncodeBlock(const NodePoints& points, NodeKey key, const Cube& cube) {
  Bytes block;
  EncodeBlock(points, key, cube, block);
  return block;
}

void EncodeBlock(const NodePoints& points, NodeKey key, const Cube& cube, Bytes& block) {
  const std::size_t n = points.size();
  if (n > std::numeric_limits<std::uint32_t>::max()) {
    throw Error::InvalidArgument("EncodeBlock: node " + key.Path() + " has " + std::to_string(n) +
                                 " points, more than a block holds (2^32 - 1)");
  }
  CheckLength("position", points.position.size(), 3 * n);
  CheckLength("smoothing", points.smoothing.size(), n);
  CheckLength("type", points.type.size(), n);
  if (!points.id.empty()) CheckLength("id", points.id.size(), n);
  if (!points.grid.empty()) CheckLength("grid", points.grid.size(), n);
  for (const ColumnId id : kVectorColumnIds) {
    const std::vector<float>& column = *VectorColumnOf(points, id);
    if (!column.empty()) CheckLength(ColumnName(id), column.size(), 3 * n);
  }
  if (!points.velocity_dispersion.empty()) {
    CheckLength(ColumnName(ColumnId::kVelocityDispersion), points.velocity_dispersion.size(), n);
  }
  if (!points.shape.empty()) CheckLength(ColumnName(ColumnId::kShape), points.shape.size(), 6 * n);
  if (!points.refine_bound.empty()) CheckLength(ColumnName(ColumnId::kRefineBound), points.refine_bound.size(), 3 * n);
  const auto& off = points.octant_offsets;
  if (off[0] != 0 || off[8] != n || !std::is_sorted(off.begin(), off.end())) {
    throw Error::InvalidArgument("EncodeBlock: octant_offsets of node " + key.Path() +
                                 " are not a partition of the points (use OrderByOctant)");
  }

  std::vector<ColumnId> ids;
  for (const ColumnId id : kColumnIds) {
    const std::vector<float>* vector = VectorColumnOf(points, id);
    const bool present = vector != nullptr                         ? !vector->empty()
                         : id == ColumnId::kId                     ? !points.id.empty()
                         : id == ColumnId::kVelocityDispersion     ? !points.velocity_dispersion.empty()
                         : id == ColumnId::kShape                  ? !points.shape.empty()
                         : id == ColumnId::kChildCluster           ? !points.child_cluster.empty()
                         : id == ColumnId::kRefineBound            ? !points.refine_bound.empty()
                                                                   : IsRequired(id);
    if (present) ids.push_back(id);
  }

  // IDs that span less than 2^32 are stored as offsets from the smallest.
  std::uint64_t id_base = 0;
  std::uint8_t id_encoding = kEncodingV1;
  if (!points.id.empty()) {
    const auto [lowest, highest] = std::minmax_element(points.id.begin(), points.id.end());
    if (*highest - *lowest <= std::numeric_limits<std::uint32_t>::max()) {
      id_base = *lowest;
      id_encoding = kEncodingIdOffsets;
    }
  }
  if (!points.child_cluster.empty()) CheckChildClusters(points, key);
  // Cluster indices fit 16 bits while the node has at most 2^16 points.
  const std::uint8_t child_cluster_encoding = n <= 65536 ? kEncodingV1 : kEncodingChildClusterU32;
  const auto encoding_of = [id_encoding, child_cluster_encoding](ColumnId id) {
    return id == ColumnId::kId ? id_encoding : id == ColumnId::kChildCluster ? child_cluster_encoding : kEncodingV1;
  };
  const auto length_of = [&](ColumnId id) { return ColumnLength(id, encoding_of(id), n, points.child_cluster.size()); };

  const std::size_t header_size = kBlockFixedHeaderSize + kBlockDirectoryEntrySize * ids.size() + 8;
  std::size_t block_size = header_size;
  for (const ColumnId id : ids) block_size += length_of(id);
  // Every column byte is written below; the header (with its unused
  // parameter bytes) is zeroed first.
  block.resize(block_size);
  std::uint8_t* b = block.data();
  std::memset(b, 0, header_size);

  PutU32(b + 0, kBlockMagic);
  PutU16(b + 4, kBlockVersion);
  PutU16(b + 6, static_cast<std::uint16_t>(header_size));
  PutU64(b + 8, block_size);
  PutU64(b + 16, key.value());
  PutU32(b + 24, static_cast<std::uint32_t>(n));
  PutU16(b + 28, static_cast<std::uint16_t>(ids.size()));
  for (int o = 0; o < 9; ++o) PutU32(b + 32 + 4 * o, off[o]);

  std::size_t offset = header_size;
  const double node_size = cube.NodeSize(key.level());
  for (std::size_t c = 0; c < ids.size(); ++c) {
    const ColumnId id = ids[c];
    std::uint8_t* entry = b + kBlockFixedHeaderSize + kBlockDirectoryEntrySize * c;
    std::uint8_t* params = entry + 32;
    std::uint8_t* out = b + offset;
    const std::size_t length = length_of(id);
    switch (id) {
      case ColumnId::kPosition: EncodePositions(points, key, cube, out); break;
      case ColumnId::kWeight:
        PutF64(params, EncodeWeights(points.weight, out));
        PutU64(params + 8, kWeightTotalUnits);
        break;
      case ColumnId::kSmoothing:
        EncodeSmoothing(points.smoothing, node_size, out);
        PutF32(params, kSmoothingLog2Min);
        PutF32(params + 4, kSmoothingPerOctave);
        break;
      case ColumnId::kId: {
        const std::uint64_t* particle_id = points.id.data();  // not reloaded after every byte store
        if (id_encoding == kEncodingIdOffsets) {
          PutU64(params, id_base);
          for (std::size_t i = 0; i < n; ++i) PutU32(out + 4 * i, static_cast<std::uint32_t>(particle_id[i] - id_base));
        } else {
          for (std::size_t i = 0; i < n; ++i) PutU64(out + 8 * i, particle_id[i]);
        }
        break;
      }
      case ColumnId::kType:
        if (n > 0) std::memcpy(out, points.type.data(), n);
        break;
      case ColumnId::kVelocity:
      case ColumnId::kDisplacement:
      case ColumnId::kNextVelocity:
      case ColumnId::kPrevDisplacement:
      case ColumnId::kPrevVelocity: EncodeRanged3(ColumnName(id), *VectorColumnOf(points, id), out, params); break;
      case ColumnId::kShape: EncodeShapes(points.shape, out); break;
      case ColumnId::kVelocityDispersion:
        EncodeNonNegativeRanged1(ColumnName(id), points.velocity_dispersion, out, params);
        break;
      case ColumnId::kChildCluster:
        PutU64(params, points.child_cluster.size());
        for (std::size_t i = 0; i < points.child_cluster.size(); ++i) {
          if (child_cluster_encoding == kEncodingV1) {
            PutU16(out + 2 * i, static_cast<std::uint16_t>(points.child_cluster[i]));
          } else {
            PutU32(out + 4 * i, points.child_cluster[i]);
          }
        }
        break;
      case ColumnId::kRefineBound: EncodeRefineBounds(points.refine_bound, out, params); break;
    }
    entry[0] = static_cast<std::uint8_t>(id);
    entry[1] = encoding_of(id);
    PutU64(entry + 8, offset);
    PutU64(entry + 16, length);
    PutU64(entry + 24, Checksum(out, length));
    offset += length;
  }
  PutU64(b + header_size - 8, Checksum(b, header_size - 8));
}

std::size_t DecodeBlockHeaderSize(std::span<const std::uint8_t> prefix, const std::string& where) {
  if (prefix.size() < kBlockFixedHeaderSize) {
    throw Error::Corruption(where, "block truncated: " + std::to_string(prefix.size()) +
                                       " bytes, the fixed header alone needs " +
                                       std::to_string(kBlockFixedHeaderSize));
  }
  const std::uint32_t magic = GetU32(prefix.data());
  if (magic != kBlockMagic) {
    throw Error::Corruption(where, "bad block magic " + std::to_string(magic) + ", expected " +
                                       std::to_string(kBlockMagic) + " (\"OCBK\")");
  }
  const std::size_t header_size = GetU16(prefix.data() + 6);
  if (header_size < kBlockFixedHeaderSize + kBlockDirectoryEntrySize + 8 || header_size > kBlockMaxHeaderSize ||
      (header_size - kBlockFixedHeaderSize - 8) % kBlockDirectoryEntrySize != 0) {
    throw Error::Corruption(where, "impossible block header size " + std::to_string(header_size));
  }
  return header_size;
}

BlockHeader DecodeBlockHeader(std::span<const std::uint8_t> prefix, NodeKey key, const std::string& where) {
  const std::size_t header_size = DecodeBlockHeaderSize(prefix, where);
  if (prefix.size() < header_size) {
    throw Error::Corruption(where, "block truncated: " + std::to_string(prefix.size()) + " bytes, the header needs " +
                                       std::to_string(header_size));
  }
  const std::uint8_t* b = prefix.data();
  // Verified before anything else is believed, so every later check sees the
  // bytes the writer wrote, and a flipped version reads as corruption.
  if (GetU64(b + header_size - 8) != Checksum(b, header_size - 8)) {
    throw Error::Corruption(where, "block header checksum mismatch");
  }
  const std::uint16_t version = GetU16(b + 4);
  if (version != kBlockVersion) {
    throw Error::NotSupported(where, "block format version " + std::to_string(version) + ", this build reads " +
                                         std::to_string(kBlockVersion));
  }
  BlockHeader header;
  header.header_size = header_size;
  header.block_size = GetU64(b + 8);
  header.key = NodeKey::FromValue(GetU64(b + 16));
  header.point_count = GetU32(b + 24);
  const std::size_t column_count = GetU16(b + 28);
  if (header.key != key) {
    throw Error::Corruption(where, "block holds node " +
                                       (header.key.IsValid() ? header.key.Path() : std::to_string(header.key.value())) +
                                       ", expected " + key.Path());
  }
  if (header_size != kBlockFixedHeaderSize + kBlockDirectoryEntrySize * column_count + 8) {
    throw Error::Corruption(where, "header size " + std::to_string(header_size) + " does not fit " +
                                       std::to_string(column_count) + " columns");
  }
  if (GetU16(b + 30) != 0 || GetU32(b + 68) != 0) throw Error::Corruption(where, "reserved header bits set");
  for (int o = 0; o < 9; ++o) header.octant_offsets[o] = GetU32(b + 32 + 4 * o);
  const auto& off = header.octant_offsets;
  if (off[0] != 0 || off[8] != header.point_count || !std::is_sorted(off.begin(), off.end())) {
    throw Error::Corruption(where, "octant offsets are not a partition of the " +
                                       std::to_string(header.point_count) + " points");
  }

  std::uint64_t expected_offset = header_size;
  ColumnSet seen = 0;
  for (std::size_t c = 0; c < column_count; ++c) {
    const std::uint8_t* entry = b + kBlockFixedHeaderSize + kBlockDirectoryEntrySize * c;
    const std::uint8_t raw_id = entry[0];
    if (raw_id == 0 || raw_id > kMaxColumnId) {
      throw Error::Corruption(where, "directory entry " + std::to_string(c) + " has unknown column id " +
                                         std::to_string(raw_id));
    }
    BlockColumn column;
    column.id = static_cast<ColumnId>(raw_id);
    if (seen & ColumnBit(column.id)) throw Error::Corruption(where, ColumnWhat(column.id, "listed twice"));
    seen |= ColumnBit(column.id);
    column.encoding = entry[1];
    if (column.encoding != kEncodingV1 && !(column.id == ColumnId::kId && column.encoding == kEncodingIdOffsets) &&
        !(column.id == ColumnId::kChildCluster && column.encoding == kEncodingChildClusterU32)) {
      throw Error::Corruption(where, ColumnWhat(column.id, "unknown encoding " + std::to_string(entry[1])));
    }
    if (GetU16(entry + 2) != 0 || GetU32(entry + 4) != 0) {
      throw Error::Corruption(where, ColumnWhat(column.id, "reserved bits set"));
    }
    column.offset = GetU64(entry + 8);
    column.length = GetU64(entry + 16);
    column.checksum = GetU64(entry + 24);
    std::memcpy(column.params.data(), entry + 32, column.params.size());
    if (column.offset != expected_offset) {
      throw Error::Corruption(where, ColumnWhat(column.id, "starts at byte " + std::to_string(column.offset) +
                                                               ", expected " + std::to_string(expected_offset)));
    }
    const std::uint64_t expected_length =
        ColumnLength(column.id, column.encoding, header.point_count,
                     column.id == ColumnId::kChildCluster ? GetU64(column.params.data()) : 0);
    if (column.length != expected_length) {
      const std::string of = column.id == ColumnId::kChildCluster
                                 ? std::to_string(GetU64(column.params.data())) + " entries"
                                 : std::to_string(header.point_count) + " points";
      throw Error::Corruption(where, ColumnWhat(column.id, std::to_string(column.length) + " bytes for " + of +
                                                               ", expected " + std::to_string(expected_length)));
    }
    expected_offset += column.length;
    header.columns.push_back(column);
  }
  if (header.block_size != expected_offset) {
    throw Error::Corruption(where, "block size " + std::to_string(header.block_size) + " but the columns end at " +
                                       std::to_string(expected_offset));
  }
  for (std::uint8_t raw_id = 1; raw_id <= kMaxColumnId; ++raw_id) {
    const auto id = static_cast<ColumnId>(raw_id);
    if (IsRequired(id) && !(seen & ColumnBit(id))) throw Error::Corruption(where, ColumnWhat(id, "required but missing"));
  }
  return header;
}

void DecodeColumn(const BlockHeader& header, ColumnId id, std::span<const std::uint8_t> bytes, const Cube& cube,
                  const std::string& where, NodePoints& out) {
  const BlockColumn* column = header.Find(id);
  if (column == nullptr) {
    throw Error::InvalidArgument(where + ": block has no column '" + ColumnName(id) + "' to decode");
  }
  VerifyColumnBytes(*column, bytes, where);
  out.octant_offsets = header.octant_offsets;
  const std::uint32_t n = header.point_count;
  const std::uint8_t* in = bytes.data();
  const std::uint8_t* params = column->params.data();
  switch (id) {
    case ColumnId::kPosition: {
      const NodeCube node = cube.NodeCubeOf(header.key);
      const double quantum = node.size / 65536.0;
      out.position.resize(3 * std::size_t{n});
      int octant = 0;
      for (std::uint32_t i = 0; i < n; ++i) {
        while (i >= header.octant_offsets[octant + 1]) ++octant;
        int point_octant = 0;
        for (int a = 0; a < 3; ++a) {
          const std::uint16_t q = GetU16(in + 6 * std::size_t{i} + 2 * a);
          point_octant |= (q >> 15) << a;
          out.position[3 * std::size_t{i} + a] = node.origin[a] + (q + 0.5) * quantum;
        }
        if (point_octant != octant) {
          throw Error::Corruption(where, ColumnWhat(id, "point " + std::to_string(i) + " lies in octant " +
                                                            std::to_string(point_octant) +
                                                            " but the octant offsets say " + std::to_string(octant)));
        }
      }
      break;
    }
    case ColumnId::kWeight: {
      const double unit = GetF64(params);
      const std::uint64_t total_units = GetU64(params + 8);
      if (!std::isfinite(unit) || unit < 0 || total_units > std::numeric_limits<std::uint32_t>::max()) {
        throw Error::Corruption(where, ColumnWhat(id, "bad parameters unit " + std::to_string(unit) + ", K " +
                                                          std::to_string(total_units)));
      }
      out.weight.resize(n);
      std::uint64_t sum = 0;
      for (std::uint32_t i = 0; i < n; ++i) {
        const std::uint32_t units = GetU32(in + 4 * std::size_t{i});
        sum += units;
        out.weight[i] = units * unit;
      }
      if (sum != (n > 0 ? total_units : 0)) {
        throw Error::Corruption(where, ColumnWhat(id, "units sum to " + std::to_string(sum) + ", expected " +
                                                          std::to_string(total_units)));
      }
      break;
    }
    case ColumnId::kSmoothing: {
      const float log2_min = GetF32(params);
      const float per_octave = GetF32(params + 4);
      if (!std::isfinite(log2_min) || !std::isfinite(per_octave) || !(per_octave > 0)) {
        throw Error::Corruption(where, ColumnWhat(id, "bad parameters log2_min " + std::to_string(log2_min) +
                                                          ", per_octave " + std::to_string(per_octave)));
      }
      const double node_size = cube.NodeSize(header.key.level());
      out.smoothing.resize(n);
      for (std::uint32_t i = 0; i < n; ++i) {
        out.smoothing[i] =
            node_size * std::exp2(static_cast<double>(log2_min) + GetU16(in + 2 * std::size_t{i}) / double{per_octave});
      }
      break;
    }
    case ColumnId::kId:
      out.id.resize(n);
      if (column->encoding == kEncodingIdOffsets) {
        const std::uint64_t base = GetU64(params);
        std::uint32_t highest = 0;
        for (std::uint32_t i = 0; i < n; ++i) {
          const std::uint32_t offset = GetU32(in + 4 * std::size_t{i});
          highest = std::max(highest, offset);
          out.id[i] = base + offset;
        }
        if (highest > std::numeric_limits<std::uint64_t>::max() - base) {
          throw Error::Corruption(where, ColumnWhat(id, "base " + std::to_string(base) + " plus offset " +
                                                            std::to_string(highest) + " passes 2^64 - 1"));
        }
      } else {
        for (std::uint32_t i = 0; i < n; ++i) out.id[i] = GetU64(in + 8 * std::size_t{i});
      }
      break;
    case ColumnId::kType: out.type.assign(in, in + n); break;
    case ColumnId::kVelocity:
    case ColumnId::kDisplacement:
    case ColumnId::kNextVelocity:
    case ColumnId::kPrevDisplacement:
    case ColumnId::kPrevVelocity: DecodeRanged3(*column, n, bytes, where, *VectorColumnOf(out, id)); break;
    case ColumnId::kVelocityDispersion:
      DecodeNonNegativeRanged1(*column, n, bytes, where, out.velocity_dispersion);
      break;
    case ColumnId::kShape: DecodeShapes(*column, n, bytes, where, out.shape); break;
    case ColumnId::kChildCluster: DecodeChildClusters(header, *column, bytes, where, out.child_cluster); break;
    case ColumnId::kRefineBound: {
      std::array<std::int32_t, 3> base{};
      for (int k = 0; k < 3; ++k) {
        base[k] = static_cast<std::int32_t>(GetU32(params + 4 * k));
        if (base[k] < kRefineBoundLowestBase || base[k] > kRefineBoundHighestBase) {
          throw Error::Corruption(where, ColumnWhat(id, "base " + std::to_string(k) + " is 2^" +
                                                            std::to_string(base[k]) + ", outside the float range"));
        }
      }
      out.refine_bound.resize(3 * std::size_t{n});
      for (std::size_t i = 0; i < out.refine_bound.size(); ++i) {
        const std::uint16_t code = GetU16(in + 2 * i);
        const float x = RefineBoundValue(base[i % 3], code);
        if (!std::isfinite(x)) {
          throw Error::Corruption(where, ColumnWhat(id, "point " + std::to_string(i / 3) + " holds code " +
                                                            std::to_string(code) + ", beyond the float range"));
        }
        out.refine_bound[i] = x;
      }
      break;
    }
  }
}

DecodedBlock DecodeBlock(std::span<const std::uint8_t> block, ColumnSet wanted, NodeKey key, const Cube& cube,
                         const std::string& where) {
  DecodedBlock decoded;
  decoded.header = DecodeBlockHeader(block, key, where);
  if (block.size() != decoded.header.block_size) {
    throw Error::Corruption(where, "block is " + std::to_string(block.size()) + " bytes, its header says " +
                                       std::to_string(decoded.header.block_size));
  }
  decoded.points.octant_offsets = decoded.header.octant_offsets;
  for (const BlockColumn& column : decoded.header.columns) {
    if (!(wanted & ColumnBit(column.id))) continue;
    DecodeColumn(decoded.header, column.id, block.subspan(column.offset, column.length), cube, where, decoded.points);
  }
  return decoded;
}

void VerifyColumnBytes(const BlockColumn& column, std::span<const std::uint8_t> bytes, const std::string& where) {
  if (bytes.size() != column.length) {
    throw Error::Corruption(where, ColumnWhat(column.id, "have " + std::to_string(bytes.size()) +
                                                             " bytes, the directory says " + std::to_string(column.length)));
  }
  if (Checksum(bytes.data(), bytes.size()) != column.checksum) {
    throw Error::Corruption(where, ColumnWhat(column.id, "checksum mismatch"));
  }
}

Bytes AssembleColumnSubset(const BlockHeader& header, ColumnSet keep,
                           std::span<const std::span<const std::uint8_t>> column_bytes) {
  if (column_bytes.size() != header.columns.size()) {
    throw Error::InvalidArgument("AssembleColumnSubset: " + std::to_string(column_bytes.size()) + " spans for " +
                                 std::to_string(header.columns.size()) + " columns");
  }
  std::vector<std::size_t> kept;
  for (std::size_t c = 0; c < header.columns.size(); ++c) {
    if (keep & ColumnBit(header.columns[c].id)) kept.push_back(c);
  }
  const std::size_t header_size = kBlockFixedHeaderSize + kBlockDirectoryEntrySize * kept.size() + 8;
  std::size_t block_size = header_size;
  for (std::size_t c : kept) {
    if (column_bytes[c].size() != header.columns[c].length) {
      throw Error::InvalidArgument(std::string("AssembleColumnSubset: column '") + ColumnName(header.columns[c].id) +
                                   "' has the wrong length");
    }
    block_size += column_bytes[c].size();
  }
  Bytes block(block_size, 0);
  std::uint8_t* b = block.data();
  PutU32(b + 0, kBlockMagic);
  PutU16(b + 4, kBlockVersion);
  PutU16(b + 6, static_cast<std::uint16_t>(header_size));
  PutU64(b + 8, block_size);
  PutU64(b + 16, header.key.value());
  PutU32(b + 24, header.point_count);
  PutU16(b + 28, static_cast<std::uint16_t>(kept.size()));
  for (int o = 0; o < 9; ++o) PutU32(b + 32 + 4 * o, header.octant_offsets[o]);
  std::size_t offset = header_size;
  for (std::size_t k = 0; k < kept.size(); ++k) {
    const BlockColumn& column = header.columns[kept[k]];
    std::uint8_t* entry = b + kBlockFixedHeaderSize + kBlockDirectoryEntrySize * k;
    entry[0] = static_cast<std::uint8_t>(column.id);
    entry[1] = column.encoding;
    PutU64(entry + 8, offset);
    PutU64(entry + 16, column.length);
    PutU64(entry + 24, column.checksum);
    std::memcpy(entry + 32, column.params.data(), column.params.size());
    if (column.length > 0) std::memcpy(b + offset, column_bytes[kept[k]].data(), column.length);
    offset += column.length;
  }
  PutU64(b + header_size - 8, Checksum(b, header_size - 8));
  return block;
}

}  // namespace octocosm
