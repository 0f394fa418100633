#pragma once
// What a mapping run hands back: each scan's outcome, the loops it tried, the stage times and the
// counters of Table I. A value built from the matcher's state when it is asked for
// (SurveyMatcher::result), never the state itself.
//
// Thread-safety: plain values.
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/registration/health.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/slam/pose_graph.hpp"

namespace minemap {

/// How one scan ended up.
struct ScanOutcome {
  std::string name;
  Pose pose_cm = Pose::Identity();          ///< final T_world_file (cm)
  Pose initial_pose_cm = Pose::Identity();  ///< the odometry pose it started from
  std::vector<io::FrameLine> frames;        ///< every pose it took, 3DTK .frames style (last = final)
  IcpResult last_match;                     ///< the last ICP run that moved it (pairwise or relaxation)
  RegistrationHealth health;                ///< how far last_match can be trusted
  int relaxation_matches = 0;               ///< step-3 matches of this scan
  /// Seconds spent when this scan arrived: its own match and (kSimultaneous) the relaxation after
  /// it; the cost per new scan (loop closing and the last relaxation are in MappingResult::times).
  double match_s = 0;
  /// The process's resident memory once this scan was matched, MB (0 where the system does not say):
  /// a long survey's memory scan by scan (report.json "memory_mb", docs/scaling.md).
  double resident_mb = 0;
  std::size_t points_in = 0;                ///< points read
  std::size_t points_used = 0;              ///< points after filtering, used for matching
  std::size_t outliers_replaced = 0;
  /// The filtered points, in the points frame (shared, not copied, between results of one run;
  /// null in an outcome read back from watch.json).
  std::shared_ptr<const std::vector<Eigen::Vector3f>> used_points_cm;
  /// Their intensities, where the scan carries them (kVoxel: each voxel's mean); null otherwise.
  std::shared_ptr<const std::vector<float>> used_intensity;
  Pose world_from_points = Pose::Identity();    ///< final T_world_points (places used_points_cm)
  /// A moving sensor's sweep: its middle on the file's clock (NaN: its points carry no times)...
  double stamp_s = std::numeric_limits<double>::quiet_NaN();
  /// ...and the motion its points were deskewed by (filter/deskew.hpp: over the whole sweep, start
  /// to end, in the file's frame, cm); empty: not deskewed.
  std::optional<Pose> sweep_motion_cm;
  bool registered = true;                   ///< false: no registration succeeded; pose from odometry
  std::string failure;                      ///< why, when !registered
  /// A survey tied to control (slam/control_tie.hpp): the covariance of world_from_points' right
  /// perturbation [translation cm, rotation rad] from the adjusted pose graph, calibrated
  /// (ControlSettings::sigma_scale). Empty otherwise.
  std::optional<Eigen::Matrix<double, 6, 6>> covariance;
};

struct StageTimes {
  double filter_s = 0, tree_build_s = 0, pairwise_s = 0, relaxation_s = 0, loop_closure_s = 0;
  double control_s = 0;  ///< the tie to control (slam/control_tie.hpp), after the matcher
  /// loop_closure_s's parts: the loop matches, the steps' information for the pose graph, its
  /// solve, the judging after it (slam/loop_closing.hpp).
  double loop_matches_s = 0, loop_graph_steps_s = 0, loop_solve_s = 0, loop_judging_s = 0;
};

/// A loop the closing step found: scan `to` stands near the earlier scan `from`.
struct LoopClosure {
  std::size_t from = 0, to = 0;
  bool closed = false;              ///< a trusted match joined them (an edge of the relaxation)
  std::string doubt;                ///< when not closed: why
  double gap_before_cm = 0, gap_before_deg = 0;  ///< where the match put `to`, against its pose before
  double path_cm = 0;  ///< the drive from `from` to `to` along the scan positions, before the relaxation
  double gap_after_cm = 0, gap_after_deg = 0;    ///< the same after the relaxation
  /// The gap before the relaxation over the drive between (0 when there was no drive).
  double misclosure_fraction() const { return path_cm > 0.0 ? gap_before_cm / path_cm : 0.0; }
  /// The same in parts per million, as a traverse's misclosure is stated.
  double misclosure_ppm() const { return 1e6 * misclosure_fraction(); }
  /// The gap's share per scan of the loop: what the relaxation moved each step by, on average (cm).
  double gap_per_scan_cm() const { return to > from ? gap_before_cm / static_cast<double>(to - from) : 0.0; }
};

/// One control point after the tie (slam/control_tie.hpp).
struct ControlResidual {
  std::string point;
  std::vector<std::size_t> scans;  ///< the scans observing it
  /// Where the map puts it minus where it is known to be: east, north, height (m). For a blunder:
  /// where the map tied to the other points puts it.
  Eigen::Vector3d residual_m = Eigen::Vector3d::Zero();
  /// That difference in its sigmas (the point's and the map's there: the 3D Mahalanobis distance).
  double sigmas = 0.0;
  double sigma_horizontal_m = 0.0, sigma_vertical_m = 0.0;  ///< the point's own, as the file gives
  bool blunder = false;  ///< left out of the tie (ControlSettings::blunder_sigmas)
  /// The closure on the control: where the map as matched, moved rigidly onto all the control
  /// (Helmert), put the point, minus where it is (east, north, height; m): what the tie then bent.
  Eigen::Vector3d before_m = Eigen::Vector3d::Zero();
};

/// A survey tied to its control: the poses are then in the grid, less `origin_cm`.
struct ControlTie {
  std::string file;
  std::optional<std::uint32_t> epsg;  ///< the grid's CRS, as the control file gives it
  /// The grid's local origin in the survey's frame and cm (3DTK's axes for a uos survey): the map's
  /// outputs add it, as they add a survey's own origin (io::Survey::origin_cm) without control.
  Eigen::Vector3d origin_cm = Eigen::Vector3d::Zero();
  std::vector<ControlResidual> residuals;  ///< one per control point observed
  int points_used = 0;                     ///< control points in the tie (blunders left out)
  /// Whether the points could be checked for blunders (4 or more observed: each predicted by 3
  /// others). With 3, a wrong point bends the map unseen: the console and report.json say so.
  bool checked_for_blunders = false;
  double rms_m = 0.0;                      ///< of the points used, 3D
  /// The map's shape as matched, moved rigidly onto the control (translation cm, rotation deg):
  /// how far the tie moved the first scan (the frame it was mapped in).
  double moved_first_scan_cm = 0.0, moved_first_scan_deg = 0.0;
  /// How far the adjustment bent the map beyond that rigid move: the largest and mean move of a
  /// scan (cm).
  double bent_max_cm = 0.0, bent_mean_cm = 0.0;
  /// The closure on the control as a traverse states it: the largest ControlResidual::before_m
  /// over the drive between the first and the last scan observing control (ppm; 0 with no drive).
  double closure_ppm = 0.0;
  double drive_cm = 0.0;  ///< that drive, along the scan positions as matched
};

/// A scan's points for the map (ScanOutcome::used_points_cm and used_intensity).
struct MapPoints {
  std::shared_ptr<const std::vector<Eigen::Vector3f>> points_cm;
  std::shared_ptr<const std::vector<float>> intensity;
};

/// Where a long run keeps the map points of the scans it let go of from memory (docs/scaling.md):
/// read back one scan at a time by whoever writes the map. Thread-safety: points_of from any thread.
class SpilledPoints {
 public:
  virtual ~SpilledPoints() = default;
  virtual MapPoints points_of(std::size_t scan) const = 0;
};

struct MappingResult {
  std::vector<ScanOutcome> scans;
  /// Where the scans whose used_points_cm are null keep them (a run with a memory bound); null: all
  /// in memory. Read them through map_points().
  std::shared_ptr<const SpilledPoints> spilled;
  std::uint64_t spilled_bytes = 0;  ///< written to the spill (report.json memory_mb.spilled)
  std::string backend;       ///< the backend that made the poses: "cpu: ..." / "opencl: <device>"
  std::string backend_note;  ///< empty, or why another backend than the one handed in made them
  std::vector<std::string> notes;  ///< fallbacks, skipped filters
  StageTimes times;
  int step1_icp_iterations = 0;  ///< Table I: ICP iterations of the pairwise step
  int step3_icp_iterations = 0;  ///< Table I: ICP iterations of the relaxation
  int relaxation_matches = 0;
  std::vector<LoopClosure> loops;  ///< every loop candidate tried (MappingSettings::loops)
  /// ControlSettings::keep_graph: the survey's pose graph over world_from_points (cm, rad): each
  /// scan's step from the scan before as matched, with its match's information, then the closed
  /// loops' edges. Empty otherwise.
  std::vector<PoseGraphEdge> graph;
  std::optional<ControlTie> control;  ///< set by tie_to_control (slam/control_tie.hpp)
  /// Stopped on request (map_survey's stop_requested) after `scans_matched` scans (0..k-1 hold their
  /// final poses; the rest are untouched); a complete run has scans_matched == scans.size().
  bool interrupted = false;
  std::size_t scans_matched = 0;
  bool all_registered() const;
  /// Scan i's map points, from memory or read back from `spilled`; null points where it has none.
  MapPoints map_points(std::size_t i) const;
  /// Indices of the registered scans whose last match was judged doubtful (ScanOutcome::health).
  std::vector<std::size_t> doubtful() const;
};

}  // namespace minemap
