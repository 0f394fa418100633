// The one source of what the C++ backend and the OpenCL kernels must agree on: sizes, the layout of
// the ICP sums, and the scalar steps whose rounding both must repeat. This header is written in the
// common subset of C++20 and OpenCL C 1.2: the C++ includes it (namespace minemap::shared), and the
// host prepends it to the kernel source (cmake/EmbedOpenCL.cmake embeds it first), so a constant
// or a step changed here changes on both sides at once.
//
// Floating point: contraction is off on both sides (OpenCL: the pragma below; C++: the targets are
// built with -ffp-contract=off), so a * b + c rounds twice everywhere, as written.
#ifndef MINEMAP_SHARED_H
#define MINEMAP_SHARED_H

#ifdef __OPENCL_C_VERSION__
#pragma OPENCL FP_CONTRACT OFF
#else
namespace minemap::shared {
#endif

// ---- sizes ----------------------------------------------------------------------------------------
/// ICP pairs are summed per block of this many consecutive data points, in double, in index order;
/// blocks are added in order. CPU (TBB over blocks) and device (one work-item per block) alike.
#define MM_PAIR_SUM_BLOCK 64
/// Brute-force search: model points staged through local memory per tile (= its work-group size).
#define MM_BRUTE_TILE 256
/// Deepest kd-tree (levels): the search stacks hold this many pending nodes. KdTree refuses deeper.
#define MM_MAX_KD_DEPTH 64
/// Largest median-filter window (points); SliceFilterSettings::validate enforces it.
#define MM_MAX_MEDIAN_WINDOW 31

// ---- the point-to-point objective's sums (search/pair_sums.hpp) ---------------------------------
// Per pair (p in the data cloud, m its closest model point, both centred on the data centroid, w
// the pair's weight: 1, or the robust kernel's): count, sum w p' (3), sum w m' (3), sum w p' m'^T
// (9, row-major), sum |p - m|^2, sum w.
#define MM_TERM_COUNT 0
#define MM_TERM_SUM_DATA 1
#define MM_TERM_SUM_MODEL 4
#define MM_TERM_SUM_DATA_MODEL 7
#define MM_TERM_SUM_SQUARED_DISTANCE 16
#define MM_TERM_WEIGHT 17
#define MM_SUM_TERMS 18

// ---- scalar steps both sides take in the same order --------------------------------------------------
/// |a - b|^2 as ((dx dx + dy dy) + dz dz).
inline float mm_squared_distance3(float ax, float ay, float az, float bx, float by, float bz) {
  const float dx = ax - bx;
  const float dy = ay - by;
  const float dz = az - bz;
  return (dx * dx + dy * dy) + dz * dz;
}

/// |p|^2 as ((x x + y y) + z z): the squared range the median filter sorts by.
inline float mm_squared_norm3(float x, float y, float z) { return (x * x + y * y) + z * z; }

/// One insertion step of the median filter's window sort: `key` (with `id`) goes into the sorted
/// keys[0..n) after every key not greater than it, so ties keep the order of arrival (index).
inline void mm_insert_sorted(float* keys, int* ids, int n, float key, int id) {
  int k = n;
  while (k > 0 && keys[k - 1] > key) {
    keys[k] = keys[k - 1];
    ids[k] = ids[k - 1];
    --k;
  }
  keys[k] = key;
  ids[k] = id;
}

#if !defined(__OPENCL_C_VERSION__) || defined(MM_HAVE_FP64)
#ifdef __OPENCL_C_VERSION__
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#endif
/// A pair's weight under the Geman-McClure kernel of scale s (squared: `scale_squared`, cm^2) at
/// squared distance d^2: (s^2 / (s^2 + d^2))^2, 1 at d = 0, 1/4 at d = s; the IRLS weight of
/// rho(d) = d^2 s^2 / (s^2 + d^2) (KISS-ICP's kernel). A scale of 0 weighs every pair 1, exactly.
inline double mm_robust_weight(float squared_distance, float scale_squared) {
  if (!(scale_squared > 0.0f)) return 1.0;
  const double ratio = (double)scale_squared / ((double)scale_squared + (double)squared_distance);
  return ratio * ratio;
}

/// Adds one pair's point-to-point terms to `acc` (MM_SUM_TERMS doubles): pc = p - reference and
/// mc = m - reference, already in double, `weight` from mm_robust_weight (w = 1 leaves every
/// product exact, so unweighted sums are the unweighted sums' bits). The order of these additions
/// is the bit-identity contract.
inline void mm_add_point_to_point_terms(double* acc, const double* pc, const double* mc, float squared_distance,
                                        double weight) {
  acc[MM_TERM_COUNT] += 1.0;
  for (int r = 0; r < 3; ++r) {
    acc[MM_TERM_SUM_DATA + r] += weight * pc[r];
    acc[MM_TERM_SUM_MODEL + r] += weight * mc[r];
  }
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) acc[MM_TERM_SUM_DATA_MODEL + 3 * r + c] += weight * pc[r] * mc[c];
  }
  acc[MM_TERM_SUM_SQUARED_DISTANCE] += (double)squared_distance;
  acc[MM_TERM_WEIGHT] += weight;
}

/// A point moved by a rigid transform in double, as a metascan's union moves each scan's model
/// points: q_r = ((R_r0 x + R_r1 y) + R_r2 z) + t_r, `rows` row-major (4 r: R_r0, R_r1, R_r2, t_r).
/// The kernel's step; the host keeps Eigen's product (R p + t), vectorised, which adds in this order
/// (MappingBackendsAgreeOnUnions holds the two to the same bits).
inline void mm_place_point(const double* rows, double x, double y, double z, double* q) {
  for (int r = 0; r < 3; ++r) q[r] = ((rows[4 * r] * x + rows[4 * r + 1] * y) + rows[4 * r + 2] * z) + rows[4 * r + 3];
}
#endif

#ifndef __OPENCL_C_VERSION__
}  // namespace minemap::shared
#endif
#endif  // MINEMAP_SHARED_H
