#pragma once
// Internal (not installed). One scan registered against the scans it is matched with, and judged
// (registration/health.hpp); a doubtful match tried again from the same start at wider bounds,
// coarse to fine (MappingSettings::retry_bound_factors), and kept only when trusted. Loop matches use
// the same coarse-to-fine step (match_from_wide_bound). Everything here returns a value and writes
// no state: the matcher places the scan (SurveyState::place / fail).
//
// Thread-safety: uses the backend, one thread at a time.
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/registration/health.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/slam/mapping_settings.hpp"
#include "minemap/slam/scan_preparation.hpp"

namespace minemap::detail {

/// A scan's registration: the match at the pair bound and, when that was doubtful, the trusted
/// retry that replaced it.
struct ScanMatch {
  IcpResult first;                 ///< from the start, at the pair bound
  std::optional<IcpResult> retry;  ///< a trusted retry at a wider bound (it replaces `first`)
  RegistrationHealth health;       ///< the verdict on the match kept (none when `first` failed)
  RegistrationHealth first_health; ///< with a retry: the verdict on `first`, which the retry replaced
  int iterations = 0;              ///< every ICP iteration spent, retries included (Table I's step 1)
  bool ok() const { return first.ok(); }
  /// The match kept: the trusted retry where there is one, else the first.
  const IcpResult& kept() const { return retry ? *retry : first; }
};

/// A match that starts at a wide bound and then runs the usual phases.
struct WideMatch {
  std::optional<IcpResult> fine;  ///< empty: an ICP run failed (`failure` says how, `failed` which)
  IcpResult failed;
  RegistrationHealth health;
  std::string failure;
  int iterations = 0;             ///< both runs'
};

/// The models a scan is matched against, for a given pair bound (a metascan is cropped by it), chosen
/// near where the scan stands (`standing`: its start for the first match, where that match put it
/// for the retries).
using ModelsForBound = std::function<std::vector<WorldModel>(float bound_cm, const Pose& standing)>;

/// How far a match goes: to ICP's least step with all the scan's points (final), or provisionally
/// (a sweep's first match, which tells its deskew the step): to MotionSettings::
/// provisional_step_factor times that step, with the probe's points where MotionSettings::
/// provisional_probe says so.
enum class Convergence { kFinal, kProvisional };

/// What a scan's matches minimise where it is not the paper's point-to-point ICP alone
/// (MotionPrediction::predict chooses them; the defaults are the paper's).
struct MatchObjectives {
  /// The robust kernel of the first wide match's coarse stage (IcpSettings::robust_scale_fraction;
  /// 0: the paper's sums). Retries, for starts out of reach, keep the paper's sums: the kernel would
  /// weigh every far pair down and hold the scan where it is.
  float coarse_kernel_fraction = 0.0f;
  /// The objective of every fine stage and of every match at the pair bound (retries' too; coarse
  /// stages stay point-to-point): the paper's point-to-point, or point-to-plane on the scan's own
  /// planes (PreparedScan::planes; point-to-point where it has none) for a moving sensor where
  /// MotionSettings::plane_objective asks for it.
  IcpObjective fine = IcpObjective::kPointToPoint;
  /// The spring that holds the sensor to the match's start in each of its ICP runs but a retry's
  /// (IcpSettings::start_spring_pairs): a timed sweep's, from its prediction and in its refinement.
  float start_spring_pairs = 0.0f;
  /// The match at the pair bound searches exactly from its first iteration (SearchMethod::kExact
  /// where the settings say kApproximate): a start where a match of the same scan converged (the
  /// deskew's refinement, MotionSettings::refine_search). Wide matches and retries keep the
  /// settings' schedule.
  bool exact_from_start = false;
};

class ScanRegistration {
 public:
  ScanRegistration(const MappingSettings& settings, ComputeBackend& backend)
      : settings_(settings), backend_(backend), icp_(settings.pairwise_icp()) {}

  /// The ICP every match of a scan against others runs (MappingSettings::pairwise_icp).
  const IcpSettings& icp() const { return icp_; }

  /// Registers `scan` from `start` and judges the match; a doubtful one is tried again from the
  /// same start at each wider bound, until one is trusted. `start_bound_cm` wider than the pair
  /// bound (the motion model's adaptive bound): the first match already starts there, coarse to fine.
  /// `objectives`: what its matches minimise (Prediction::objectives).
  ScanMatch register_scan(const PreparedScan& scan, const Pose& start, const ModelsForBound& models_for,
                          float start_bound_cm = 0.0f, Convergence convergence = Convergence::kFinal,
                          const MatchObjectives& objectives = {}) const;

  /// ICP at `bound_cm` from `start` (no refinement), then the usual phases from where that ended,
  /// judged with the reach of the wide bound. `coarse_on_probe`: the first ICP on the health probe's
  /// points (MotionSettings::wide_coarse_probe); `objectives`: that ICP's robust kernel and the
  /// objective of the phases after it.
  WideMatch match_from_wide_bound(const PreparedScan& scan, const Pose& start, std::span<const WorldModel> models,
                                  float bound_cm, Convergence convergence = Convergence::kFinal,
                                  bool coarse_on_probe = false, const MatchObjectives& objectives = {}) const;

  /// The health of `scan` at `pose`, moved there from `start`, against `models`, at the pair bound
  /// (the reach test at `reach_bound_cm` when > 0).
  RegistrationHealth judge(const PreparedScan& scan, const Pose& pose, const Pose& start,
                           std::span<const WorldModel> models, float reach_bound_cm = 0.0f) const;

 private:
  /// The points a match of `scan` moves: all of them, or the probe's for a provisional match.
  const PreparedCloud& data_of(const PreparedScan& scan, Convergence convergence) const;
  /// The ICP for `scan`: icp_, asking for no more pairs than the points matched allow
  /// (MappingSettings::min_pairs_for), converging as asked.
  IcpSettings icp_for(const PreparedScan& scan, Convergence convergence) const;
  /// register_icp of `data` (the scan's cloud or its probe) with `objective`: point-to-plane takes
  /// the normal of each point's cell among the scan's planes (zero where none), and is point-to-
  /// point for a scan without planes.
  IcpResult run_icp(const PreparedScan& scan, const PreparedCloud& data, const Pose& start,
                    std::span<const WorldModel> models, IcpSettings icp, IcpObjective objective) const;

  const MappingSettings& settings_;
  ComputeBackend& backend_;
  IcpSettings icp_;
};

}  // namespace minemap::detail
