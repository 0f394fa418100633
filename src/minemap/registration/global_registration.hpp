#pragma once
// Registration without a start: two clouds described by their FPFH features
// (registration/fpfh.hpp), paired by the nearest feature (each way, kept where both agree), and
// the rigid transform found by RANSAC over those pairs (Fischler and Bolles 1981; the pipeline of
// Rusu et al. 2009, as Open3D's registration_ransac_based_on_feature_matching): three pairs at a
// time, kept when their edge lengths agree, the pose by Horn's method (registration/horn.hpp, the
// paper's), scored by the pairs it brings within inlier_distance_voxels cubes. The best pose is refined on its
// inliers. It is a start for ICP, not a result: its error is a cube's size.
//
// A self-similar place (a straight drive whose walls look alike metres apart) has more than one
// good answer; a pose is returned only when it is clearly the best: the best hypothesis distinct
// from it (moving the data's points farther than distinct_voxels cubes, RMS) holds at most 1 / min_uniqueness of its
// inliers.
//
// Deterministic: a fixed seed, sampled with the generator's raw output (no distribution, whose
// algorithm the standard leaves open); parallel only where each slot is written by one task.
// Units: cm. Thread-safety: a pure function.
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/registration/fpfh.hpp"

namespace minemap {

struct GlobalRegistrationSettings {
  FeatureSettings features;
  float inlier_distance_voxels = 1.5f;  ///< a pair agrees with a pose within this many cubes
  /// Three pairs are a hypothesis only when each edge between them in one cloud is within this
  /// fraction of the same edge in the other (a rigid motion keeps lengths).
  double edge_similarity = 0.9;
  /// At most this many data features look for a partner (evenly spaced): the search is brute
  /// force, data x model features. 0: all.
  int max_data_features = 3000;
  int max_iterations = 100000;       ///< hypotheses at most...
  int min_iterations = 2000;         ///< ...and at least (the rival needs a chance to show itself)
  double confidence = 0.999;         ///< ...stopping once the best's inlier share makes a better one this unlikely
  /// Fewer: nothing found. A car's steps on KITTI 07 held 43-122 (of 500); a sweep of a simulated
  /// drive against its local map 15-21, and 21 was 12 degrees off (docs/benchmarks.md).
  int min_inliers = 40;
  double min_uniqueness = 2.0;       ///< best inliers / best distinct rival's, at least
  float distinct_voxels = 6.0f;      ///< hypotheses this many cubes apart (RMS over the data) are distinct
  float inlier_distance_cm() const { return inlier_distance_voxels * features.voxel_cm; }
  float distinct_cm() const { return distinct_voxels * features.voxel_cm; }
  std::uint64_t seed = 1;
  /// Throws std::invalid_argument naming the bad setting.
  void validate() const;
  bool operator==(const GlobalRegistrationSettings&) const = default;
};

/// One global registration.
struct GlobalRegistrationResult {
  bool found = false;
  Pose model_from_data = Pose::Identity();  ///< T_model_data, when found (the best hypothesis otherwise)
  std::size_t data_features = 0;
  std::size_t model_features = 0;
  std::size_t correspondences = 0;  ///< feature pairs RANSAC drew from
  std::size_t inliers = 0;          ///< of them, within inlier_distance_cm() at the refined pose
  std::size_t rival_inliers = 0;    ///< the best distinct hypothesis's
  int iterations = 0;
  std::string why_not;              ///< when not found: which test failed, with its figures
};

/// The feature pairs: for each of at most `max_data_features` data features (evenly spaced; 0:
/// all) its nearest model feature (squared L2, brute force), kept where that model feature's
/// nearest data feature is the same one; all of them when fewer than `min_mutual` agree so (a
/// small overlap). Ascending data index.
std::vector<std::pair<std::uint32_t, std::uint32_t>> feature_pairs(const FeatureCloud& data,
                                                                   const FeatureCloud& model,
                                                                   std::size_t min_mutual,
                                                                   std::size_t max_data_features = 0);

/// Where `data` lies in `model`'s frame, from their features alone.
GlobalRegistrationResult register_globally(const FeatureCloud& data, const FeatureCloud& model,
                                           const GlobalRegistrationSettings& settings);

}  // namespace minemap
