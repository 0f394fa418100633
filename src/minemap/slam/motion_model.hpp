#pragma once
// Internal (not installed). Where a scan's match starts, how wide it first looks, and how the
// sensor moved during its sweep. A stop-and-go survey starts each scan where the odometry says
// (3DTK's correction: the previous registered pose moved by the odometry step). A sequence with no
// odometry (a moving LiDAR's sweeps read with no poses) starts each scan at the previous registered
// pose moved by the previous registered step again (constant velocity, as KISS-ICP), scaled by the
// sweeps' times where the files carry them; its first match then looks as wide as recent
// predictions were off (KISS-ICP's adaptive threshold), so a fast hand-held sweep and a slow robot
// both start within reach. Along a direction the last timed sweep's match could not pin, the
// last step is not repeated (it would repeat its error): the recent well-pinned steps' mean move
// along it is (MotionSettings::weak_step_constraint); a timed sweep's match may also be held to
// its start by a spring (MotionSettings::sweep_start_spring_pairs: a narrow-field sweep, weaker
// as the recent predictions were off). The same constant velocity over one sweep is what the
// deskew undoes (filter/deskew.hpp). And it sums how far the recent sweeps turned about axes their
// matches could hardly pin (unpinned_turn: a doubt's figure).
//
// Reads the state, writes nothing. Thread-safety: const, one thread at a time with the state.
#include <cstddef>
#include <optional>

#include "minemap/core/pose.hpp"
#include "minemap/slam/mapping_settings.hpp"
#include "minemap/slam/scan_registration.hpp"
#include "minemap/slam/survey_state.hpp"

namespace minemap::detail {

/// How far the motion model's recent predictions were off: the RMS displacement of the points from
/// each predicted start to its trusted match (RegistrationHealth::moved_cm), over the last
/// adaptive_bound_window scans.
struct PredictionError {
  double rms_cm = 0.0;              ///< RMS of the points' displacement, prediction to match
  double translation_rms_cm = 0.0;  ///< RMS of the sensor's own displacement (the correction's translation)
  int count = 0;  ///< trusted matches it is taken over (0: no history yet)
};

/// Where scan i's match starts.
struct Prediction {
  Pose start = Pose::Identity();  ///< T_world_points
  bool constant_velocity = false; ///< predicted from the previous steps, not from odometry
  float start_bound_cm = 0.0f;    ///< the pair bound its first match starts at (>= the pair bound)
  /// What its matches minimise. The robust kernel of the first match's coarse stage:
  /// MotionSettings::wide_coarse_kernel_fraction for a keyframe without times whose bound was
  /// learned from trusted matches (a start as near as the recent ones were); 0 (the paper's sums)
  /// before there are any, and for timed sweeps. The fine objective: fine_objective().
  MatchObjectives objectives;
};

/// How far the recent timed sweeps' matches turned the sensor about axes their surfaces hardly pin
/// (MotionSettings::max_unpinned_turn_deg).
struct UnpinnedTurn {
  double deg = 0.0;         ///< the steps' turns about each match's weakest axis, summed (each's size)
  int sweeps = 0;           ///< how many steps
  double seconds = 0.0;     ///< from the first step's start to scan i's stamp
  double constraint = 0.0;  ///< scan i's rotation constraint
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();  ///< scan i's weakest axis, its data frame
};

class MotionPrediction {
 public:
  explicit MotionPrediction(const MappingSettings& settings) : settings_(settings) {}

  /// Scan i (i >= 1, in the state) predicted from scans i-1 and i-2 as they stand now.
  Prediction predict(const SurveyState& state, std::size_t i) const;
  /// The other model's start for scan i, for a second opinion on a match that landed far from the
  /// prediction: the odometry step where constant velocity predicted it, and standing still (the
  /// previous scan's pose) where the odometry did.
  Pose alternative_start(const SurveyState& state, std::size_t i) const;
  /// How far the predictions before scan i were off.
  PredictionError recent_error(const SurveyState& state, std::size_t i) const;
  /// Whether scan i starts by constant velocity (MotionSettings::model; kAuto: no scan up to i
  /// carries odometry of its own).
  bool constant_velocity_at(const SurveyState& state, std::size_t i) const;
  /// The cell scan i's metascans are thinned to, cm: a moving sensor's (a timed sweep, or a scan
  /// placed by constant velocity: no odometry) MotionSettings::local_map_cell_cm; 0 (every point,
  /// as the paper) for a stop-and-go survey's. (A keyframe's recovery describes its features on
  /// every point: thinned, its FPFH start was worse on 3 of the 4 real sequences.)
  double local_map_cell_cm(const SurveyState& state, std::size_t i) const;
  /// Whether scan i is a moving sensor's: a timed sweep, or a scan constant velocity places (no
  /// odometry). Stop-and-go surveys keep the paper's matching.
  bool moving(const SurveyState& state, std::size_t i) const;
  /// What scan i's matches minimise after their coarse stage (MatchObjectives::fine), whatever
  /// their start: point-to-plane for a moving sensor's scan where MotionSettings::plane_objective
  /// asks for it, the paper's point-to-point otherwise. The one place that chooses it.
  IcpObjective fine_objective(const SurveyState& state, std::size_t i) const;
  /// The spring that holds scan i's sensor to its match's start (MatchObjectives::
  /// start_spring_pairs): MotionSettings::sweep_start_spring_pairs for a timed sweep whose points
  /// span less azimuth than sweep_spring_max_field_deg, scaled down by the square of the recent
  /// predictions' error beyond sweep_spring_full_error_cm; none before confirm_min_history trusted
  /// matches, nor for any other scan. The one place that chooses it.
  float start_spring_pairs(const SurveyState& state, std::size_t i) const;
  /// The sensor's motion over scan j's sweep (start to end, its own file frame, cm) if it stood at
  /// T_world_points `pose_j` and scan `other` (j-1 or j+1) where the state holds it: the step
  /// between them at constant velocity, scaled by the sweep's duration over the time between their
  /// stamps (sweeps back to back, a spinning sensor's, where their stamps are not known).
  Pose sweep_motion(const SurveyState& state, std::size_t j, const Pose& pose_j, std::size_t other) const;
  /// The turn of the steps into scan i and the sweeps before it within unpinned_turn_window_s whose
  /// matches each pinned their weakest turn less than unpinned_turn_constraint of the best, about
  /// those axes; empty when scan i is no timed sweep, its own match pinned every turn, or the test
  /// is off. Each step's rotation vector is projected on its scan's weakest axis (the axis of a
  /// step's rotation is the same in both its scans' frames) and its size summed: a sensor standing
  /// still had its matches turned back and forth, 8-20 deg a sweep, that a signed sum hides.
  std::optional<UnpinnedTurn> unpinned_turn(const SurveyState& state, std::size_t i) const;

 private:
  /// T_world_file of scan i at T_world_points `world_from_points`.
  static Pose file_pose(const SurveyState& state, std::size_t i, const Pose& world_from_points);
  /// (time from scan a to scan b) / (time from scan c to scan d), where every stamp is known and
  /// both gaps are positive; `fallback` otherwise.
  static double time_ratio(const SurveyState& state, std::size_t a, std::size_t b, std::size_t c, std::size_t d,
                           double fallback);
  /// The adaptive bound for scan i: adaptive_bound_sigmas x the RMS displacement of the trusted
  /// constant-velocity predictions among the last window scans; 0 without any.
  float adaptive_bound_cm(const SurveyState& state, std::size_t i) const;
  /// The step from scan i-2 to i-1 (T_points(i-2)_points(i-1)) that constant velocity repeats for
  /// timed sweep i, its move along the direction scan i-1's match pinned weakly replaced by the
  /// recent well-pinned steps' mean (MotionSettings::weak_step_constraint); nothing where that does
  /// not apply.
  std::optional<Pose> step_along_weak_direction(const SurveyState& state, std::size_t i) const;

  const MappingSettings& settings_;
};

/// Whether scan i's prepared points span less azimuth than `max_field_deg` about its sensor (the z
/// axis of its file's frame; 5 deg bins, each holding at least 1 in 500 of them): a narrow-field
/// sensor's sweep, a rosette scanner's (~70 deg), not a spinning one's (360). Every scan is narrow
/// at 360 or more; a scan with no prepared cloud is not. The spring (start_spring_pairs) and the
/// loop match's visit (LoopClosureSettings::visit_sweeps) ask it with
/// MotionSettings::sweep_spring_max_field_deg.
bool narrow_field(const SurveyState& state, std::size_t i, double max_field_deg);

/// A match's pose with its move from the prediction along one direction taken out: T_world_points
/// `predicted` times the correction predicted -> `matched`, less that correction's translation along
/// `direction` (unit, in the predicted points' frame; the rest of the translation and the whole
/// rotation kept). `along_cm` receives the part taken out. Where a match that slid along the
/// direction its surfaces pin least starts again (SurveyMatcher::prefer_prediction_along_slide).
Pose without_move_along(const Pose& predicted, const Pose& matched, const Eigen::Vector3d& direction,
                        double* along_cm = nullptr);

}  // namespace minemap::detail
