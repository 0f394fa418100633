#pragma once
// Internal (not installed). A lost scan found again (MappingSettings::recovery): where it lies in
// the local map around the previous scan, from the shape of its surfaces alone (FPFH features and
// RANSAC, registration/global_registration.hpp), with no start. The matcher then matches it from
// there as any scan and keeps that match only when it is trusted.
//
// Reads the state, writes nothing. Thread-safety: uses the backend (the local map's tree), one
// thread at a time.
#include <cstddef>

#include "minemap/registration/global_registration.hpp"
#include "minemap/slam/local_map.hpp"
#include "minemap/slam/mapping_settings.hpp"
#include "minemap/slam/survey_state.hpp"

namespace minemap::detail {

/// A start found without one.
struct RecoveredStart {
  GlobalRegistrationResult global;  ///< its figures (found, inliers, rival, why not)
  Pose start = Pose::Identity();    ///< T_world_points of scan i, when found
};

class Recovery {
 public:
  Recovery(const MappingSettings& settings, const LocalMap& local_map) : settings_(settings), local_map_(local_map) {}

  /// Scan i (i >= 1) in the local map of the registered scans before it, around scan i-1: every
  /// model point within the scan's box at scan i-1's pose grown by RecoverySettings::reach_cm.
  RecoveredStart find(const SurveyState& state, std::size_t i) const;

 private:
  const MappingSettings& settings_;
  const LocalMap& local_map_;
};

/// RMS distance the points of `cloud` move between T_world_points `from` and `to` (cm).
double rms_moved_cm(const PreparedCloud& cloud, const Pose& from, const Pose& to);

}  // namespace minemap::detail
