#pragma once
// The sums of the point-to-point objective of ICP (paper, eq. (1)): E(R, t) = sum_i |m_i - (R d_i + t)|^2
// over the closest-point pairs (d_i in the data cloud, m_i in the model). What each pair contributes
// is written once, in minemap/shared/minemap_shared.h (mm_add_point_to_point_terms), and used by both
// backends: the backends only add MM_SUM_TERMS numbers per block of pairs, in a fixed order; they
// do not know what the numbers mean. Horn's method (registration/horn.hpp) reads them through
// PairSums. Another objective (point-to-plane, say) is another set of terms and another reader; the
// search and the reduction stay as they are. Here, below the backend (search/), because a backend
// returns them: registration/ builds on the backend, not the other way round.
#include <Eigen/Core>

#include "minemap/shared/minemap_shared.h"

namespace minemap {

inline constexpr int kSumTerms = MM_SUM_TERMS;
/// Pairs are summed per block of this many consecutive data points, in double and in index order,
/// and the blocks are added in order: the CPU backend does so (TBB over blocks, so any thread count
/// gives the same bits), and the OpenCL backend does the same per work-item on devices with double
/// precision, so the two backends' sums, and hence their poses, are bit-identical.
inline constexpr int kPairSumBlock = MM_PAIR_SUM_BLOCK;

/// The point-to-point sums over a set of pairs (p in the data cloud, m its closest model point,
/// both in the data frame), centred on `reference_cm`: p' = p - r, m' = m - r, each pair weighted
/// by w (1, or a robust kernel's weight: PairingSettings::robust_scale_cm). Held in double.
struct PairSums {
  double count = 0.0;                                         ///< pairs
  Eigen::Vector3d sum_data = Eigen::Vector3d::Zero();         ///< sum of w p'
  Eigen::Vector3d sum_model = Eigen::Vector3d::Zero();        ///< sum of w m'
  Eigen::Matrix3d sum_data_model = Eigen::Matrix3d::Zero();   ///< sum of w p' m'^T
  double sum_squared_distance_cm2 = 0.0;                      ///< sum of |p - m|^2 (unweighted)
  double weight = 0.0;                                        ///< sum of w (= count when unweighted)
  Eigen::Vector3d reference_cm = Eigen::Vector3d::Zero();

  double rms_cm() const;
  PairSums& operator+=(const PairSums& other);  ///< both must share reference_cm

  /// Decodes a record of kSumTerms terms (the layout of minemap_shared.h: MM_TERM_*), as the
  /// backends write them, in double (one block's sums) or float (a device without fp64).
  template <typename T>
  static PairSums from_terms(const T* terms, const Eigen::Vector3d& reference_cm) {
    PairSums sums;
    sums.reference_cm = reference_cm;
    sums.count = terms[MM_TERM_COUNT];
    for (int r = 0; r < 3; ++r) {
      sums.sum_data[r] = terms[MM_TERM_SUM_DATA + r];
      sums.sum_model[r] = terms[MM_TERM_SUM_MODEL + r];
      for (int c = 0; c < 3; ++c) sums.sum_data_model(r, c) = terms[MM_TERM_SUM_DATA_MODEL + 3 * r + c];
    }
    sums.sum_squared_distance_cm2 = terms[MM_TERM_SUM_SQUARED_DISTANCE];
    sums.weight = terms[MM_TERM_WEIGHT];
    return sums;
  }
};

}  // namespace minemap
