#pragma once
// Pose errors of an estimated trajectory against a reference: what report.json's "truth" holds and
// the accuracy tests and benchmarks measure.
//
// Thread-safety: a pure function.
#include <vector>

#include "minemap/core/pose.hpp"

namespace minemap {

/// Pose errors of `estimated` against `reference`, both expressed relative to scan 0 (the master
/// fixes the frame): translation in cm, rotation in degrees.
struct PoseErrors {
  double mean_translation_cm = 0, max_translation_cm = 0;
  double mean_rotation_deg = 0, max_rotation_deg = 0;
  double mean_relative_translation_cm = 0, max_relative_translation_cm = 0;  ///< consecutive pairs
  double mean_relative_rotation_deg = 0, max_relative_rotation_deg = 0;
  double path_length_cm = 0;  ///< along the reference
};
/// Throws std::invalid_argument when the two differ in count or are empty.
PoseErrors pose_errors(const std::vector<Pose>& estimated, const std::vector<Pose>& reference);

}  // namespace minemap
