#pragma once
// Everything map_survey takes (paper, section IV.B, and what minemap adds around it): the matching
// mode, the reduction, the ICP, the relaxation, loop closing and the health check; the presets; the
// ICPs derived from them (pairwise_icp(), relaxation_icp()); validation. Every default is a member
// initialiser here (or in the struct it embeds), written once; the command line binds its options
// to these fields, so `minemap map --help` shows them, and report.json records them.
//
// Thread-safety: plain values.
#include <string>
#include <vector>

#include "minemap/core/name_table.hpp"
#include "minemap/filter/deskew.hpp"
#include "minemap/filter/slice_filter.hpp"
#include "minemap/registration/global_registration.hpp"
#include "minemap/registration/health.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/registration/sweep_fit.hpp"
#include "minemap/search/kdtree.hpp"
#include "minemap/slam/pose_graph.hpp"

namespace minemap {

enum class MatchingMode { kPairwise, kIncremental, kSimultaneous };
inline constexpr std::array<EnumName<MatchingMode>, 3> kMatchingModeNames{
    {{MatchingMode::kPairwise, "pairwise"},
     {MatchingMode::kIncremental, "incremental"},
     {MatchingMode::kSimultaneous, "simultaneous"}}};
const char* to_string(MatchingMode mode);
MatchingMode parse_matching_mode(const std::string& text);  ///< a name of kMatchingModeNames

/// Which timed sweeps' refinements (the match after the deskew, from where the sweep's first match
/// converged) search exactly from their first iteration, without the paper's approximate phase.
enum class RefineSearch {
  kPapers,     ///< none: every refinement keeps the paper's schedule, approximate first
  kWideExact,  ///< a wide field's (a spinning sensor's: not narrow_field); a narrow field's the paper's
  kExact,      ///< every sweep's
};
inline constexpr std::array<EnumName<RefineSearch>, 3> kRefineSearchNames{
    {{RefineSearch::kPapers, "papers"}, {RefineSearch::kWideExact, "wide-exact"}, {RefineSearch::kExact, "exact"}}};
const char* to_string(RefineSearch search);
RefineSearch parse_refine_search(const std::string& text);  ///< a name of kRefineSearchNames

/// How each scan is reduced before matching.
enum class Reduction {
  kSlices,  ///< the paper's slice filter (median, 10 cm along each slice, every third slice)
  kVoxel,   ///< the mean of each voxel_cm cell, every point (filter/voxel_filter.hpp), as slam6D's octree
};
inline constexpr std::array<EnumName<Reduction>, 2> kReductionNames{
    {{Reduction::kSlices, "slices"}, {Reduction::kVoxel, "voxel"}}};
const char* to_string(Reduction reduction);
Reduction parse_reduction(const std::string& text);  ///< a name of kReductionNames

/// The named starting points of MappingSettings (MappingSettings::preset).
enum class Preset {
  kDefault,       ///< MappingSettings{}: voxel means, the metascan, loops
  kSimultaneous,  ///< the paper's relaxation on slice-filtered scans, minemap's ICP
  kPaper,         ///< the paper's method as published
};
inline constexpr std::array<EnumName<Preset>, 3> kPresetNames{
    {{Preset::kDefault, "default"}, {Preset::kSimultaneous, "simultaneous"}, {Preset::kPaper, "paper"}}};
const char* to_string(Preset preset);
Preset parse_preset(const std::string& text);  ///< a name of kPresetNames

/// Where a scan's match starts (slam/motion_model.hpp).
enum class MotionModel {
  /// kOdometry where the scans carry odometry, kConstantVelocity where they do not (every initial
  /// pose so far equal to the first scan's: a sequence read with no poses).
  kAuto,
  /// The previous scan's registered pose moved by the odometry step (3DTK's correction).
  kOdometry,
  /// The previous scan's registered pose moved by the previous registered step again, scaled by the
  /// scans' times where they are known (KISS-ICP's constant velocity).
  kConstantVelocity,
};
inline constexpr std::array<EnumName<MotionModel>, 3> kMotionModelNames{
    {{MotionModel::kAuto, "auto"},
     {MotionModel::kOdometry, "odometry"},
     {MotionModel::kConstantVelocity, "constant-velocity"}}};
const char* to_string(MotionModel model);
MotionModel parse_motion_model(const std::string& text);  ///< a name of kMotionModelNames

/// The motion model, the adaptive pair bound and the deskew of a moving sensor's sweeps.
struct MotionSettings {
  MotionModel model = MotionModel::kAuto;
  /// Constant velocity: the first match of a scan starts at a pair bound of this many times the
  /// RMS of how far recent predictions were off (the points' RMS displacement from the predicted
  /// start to the trusted match, KISS-ICP's adaptive threshold), when that is wider than the pair
  /// bound: a hand-held sweep that turns 6 degrees a step starts within reach, a slow robot keeps
  /// the pair bound. Never wider than the widest retry. 0: off.
  double adaptive_bound_sigmas = 3.0;
  int adaptive_bound_window = 20;  ///< ...over the trusted matches of the last this many scans
  /// ...and before there is any (the first two steps), this wide (KISS-ICP's initial threshold):
  /// the speed is not known yet, and a spinning sensor moving a metre a sweep down a tunnel, matched
  /// at 25 cm from standing still, settles on the tunnel's walls where it started, and looks right.
  double initial_bound_cm = 200.0;
  /// Scans whose points carry their times within one sweep are deskewed (filter/deskew.hpp) by the
  /// constant-velocity motion of the step into them, and again by the registered step.
  DeskewMode deskew = DeskewMode::kAuto;
  /// Times spanning more than this are not one sweep of a moving sensor (a tilting scanner or a
  /// TLS, standing while it scans): not deskewed.
  double max_sweep_s = 1.0;
  /// A sweep is deskewed again, and matched again, when its registered step's motion over the sweep
  /// differs from the predicted one by more than this (at the sweep's end)...
  double refine_min_change_cm = 1.0;
  double refine_min_change_deg = 0.1;  ///< ...or turns more than this
  /// A sweep's first match only has to tell the refinement its step: > 1 lets it converge at steps
  /// this many times ICP's least step (--min-step-cm/-deg), and the refinement's match (always run
  /// then) converges fully. 3 spends 20-30 % fewer iterations on the moving drives at their accuracy,
  /// but changes the chaotic loops: the spinning loop then closes within 0.2 % while 2 % off, and
  /// passes every test (docs/benchmarks.md, "Moving LiDAR"). 1: off, the default.
  double provisional_step_factor = 1.0;
  /// A sweep's first match matches only the health probe's points (every health.probe_stride-th
  /// data point; all of them when the health check is off): what it must tell the refinement, the
  /// step, it tells from a quarter of the points, and the refinement's match (always run then) matches
  /// all of them. Its retries, its confirmation and its recovery match the probe as well. On the
  /// simulated drives 0.68-0.85x the wall time at the same accuracy (docs/benchmarks.md, "Moving LiDAR").
  bool provisional_probe = true;
  /// Whether a sweep's first match is provisional (by either setting above): then its refinement
  /// always matches again, to ICP's least step, with all points.
  bool provisional() const { return provisional_step_factor > 1.0 || provisional_probe; }
  /// Which sweeps' refinements search exactly from their first iteration (RefineSearch). The
  /// paper's approximate phase is for a start far from the answer; from a converged one it leads
  /// away (the approximate kd-tree pairs with its buckets' means, whose minimum is not the
  /// points') and the exact phase walks back: on the simulated spinning drive the refinement spent
  /// 4.4 approximate and 10.0 exact iterations, and 7.0 exact ones searching exactly, for 0.93-0.96x
  /// the wall time, the drives as accurate. Not the default: the chaotic loops move both ways with
  /// it, two of six hand-held loops past 1 % of their paths, and one of six spinning loops lost its
  /// track (named, exit 13) where the paper's schedule stayed within 1.1 % (docs/benchmarks.md,
  /// "The refinement's exact search", "A spinning sensor's local map kept for the sweep after it").
  /// Only with SearchMethod::kApproximate (the others are already exact).
  RefineSearch refine_search = RefineSearch::kPapers;
  /// The first match at the adaptive bound (wider than the pair bound) runs its coarse stage, at
  /// that bound, on the health probe's points alone: it only has to bring the scan within the pair
  /// bound's reach, and the fine stage after it matches every point. On real hand-held keyframes
  /// (no times: every match is final) the coarse stage was more than half of the iterations at a
  /// bound of metres; docs/benchmarks.md, "Moving LiDAR", has the figures. Retries and loop matches
  /// (stop-and-go surveys' too) keep all points.
  bool wide_coarse_probe = true;
  /// A keyframe's first match at an adaptive bound learned from trusted matches (a scan without
  /// times that constant velocity places) weighs each pair of its coarse stage by the Geman-McClure
  /// kernel at this fraction of the bound (IcpSettings::robust_scale_fraction): at a bound of
  /// metres, the wrong pairs of far surfaces pull the point-to-point minimum off, and the fine
  /// stage then creeps back. On the real hand-held keyframes 0.78-0.97x the wall time, every loop
  /// within 0.3 % of its path at three voxel sizes (unweighted: 3 of 6); on BALM's sweeps
  /// 1.03-1.11x (docs/benchmarks.md, "A robust kernel in the coarse stage"). Not before the bound
  /// is learned, nor in the retries (starts out of reach, KITTI 07's keyframes from the identity):
  /// there the kernel weighs every far pair down and holds the scan where it is. Nor for timed
  /// sweeps (their deskew matches again; the simulated spinning loop no longer closed). Loop
  /// matches and stop-and-go surveys keep the paper's sums. 0: off.
  double wide_coarse_kernel_fraction = 0.6;
  /// A moving sensor's matches (a timed sweep's, or a scan's that constant velocity places: no
  /// odometry) minimise, after their coarse stage, the distances of the model's points to the
  /// scan's own planes (point-to-plane, IcpObjective::kPointToPlane; its planes are the health
  /// check's cells, MappingSettings::plane_cell_cm) instead of the paper's point-to-point distances.
  /// Not the default: on the simulated hand-held drives (timed sweeps) the mean error falls 1.5-2.4x
  /// and on the real keyframes the step error on 9 of 12 runs, but there it took 0.87-1.23x the
  /// time and 3 of the 12 runs ended doubtful where point-to-point ended none (docs/benchmarks.md,
  /// "Point-to-plane for a moving sensor"). Coarse stages, loop matches and
  /// stop-and-go surveys with odometry keep the paper's ICP either way.
  bool plane_objective = false;
  /// A moving sensor's metascan (a timed sweep's, or a scan's that constant velocity places: no
  /// odometry) keeps at most one model point in each cell of this size (the nearest scan's): its
  /// scans overlap tens of times, and a tree over all their points costs more to build than the
  /// match it serves (KISS-ICP's voxel map thins the same way). Stop-and-go surveys with odometry
  /// keep every point, as the paper. 0: all. Figures: docs/benchmarks.md, "Moving LiDAR".
  double local_map_cell_cm = 10.0;
  /// A wide-field timed sweep's metascan (a spinning sensor's: not narrow_field at
  /// sweep_spring_max_field_deg) serves up to this many sweeps in a row, its own and those after it
  /// while their boxes stay within its margin and no scan in it has moved: it is built grown by the
  /// move the last step predicts for them, and it serves their first matches and refinements at any
  /// bound up to its own. The sweeps after it match without the newest sweeps, which a spinning
  /// sensor's map hardly misses: on the simulated spinning drives 0.85-0.88x the wall time at the
  /// same mean error (the step error up to 1.1x; a loop's time is its loop closing's, 1.01x). A
  /// narrow field's newest sweep is the only one that saw what lies ahead: hand-held sweeps and
  /// keyframes take one metascan each (the hand-held loops drifted further without it). 1: one for
  /// every sweep, as the paper's (docs/benchmarks.md, "A spinning sensor's local map kept for the
  /// sweep after it").
  int local_map_sweeps = 2;
  /// A match that needed a retry and moved the scan's points more than this many times the RMS of
  /// the recent prediction errors (with at least confirm_min_history of them) is not trusted on its
  /// point statistics alone: a second match from the other model's start (standing still, or the
  /// odometry) must end within confirm_agree_cm / _deg of it, or it is doubtful. A 4 m retry can
  /// settle a corridor's surfaces onto each other metres from the truth and look perfect. So is a
  /// constant-velocity match (no retry) that moved the sensor itself more than this many times the
  /// RMS of the recent matches' translation from their predictions (and more than the pair bound):
  /// a wide first match slides along a corridor as a retry does; when the second match disagrees
  /// and ends within that jump of the prediction, it is kept instead.
  double confirm_sigmas = 6.0;
  int confirm_min_history = 3;
  double confirm_agree_cm = 5.0;
  double confirm_agree_deg = 0.5;
  /// A constant-velocity match whose pairs' planes pin its weakest translation less than this
  /// fraction of its best (RegistrationHealth::translation_constraint) and that moved the scan more
  /// than the pair bound along it is matched again from the prediction along that direction; the
  /// second match is kept when trusted, nearer the prediction along it and a closer fit
  /// (SurveyMatcher::prefer_prediction_along_slide). On real hand-held walks (a narrow-field sensor
  /// in corridors) matches slid metres along such a direction and were trusted; the simulated mines
  /// pin it better (docs/benchmarks.md, "Moving LiDAR"). 0: off.
  double slide_constraint = 0.05;
  /// ...and kept only where its pairs' RMS distance is below this times the first match's: a clearly
  /// closer fit, not one within the noise of two fits alike.
  double slide_rms_factor = 0.95;
  /// A timed sweep's constant-velocity prediction does not repeat the last step along the
  /// direction the last match pinned weakly (RegistrationHealth::translation_constraint below this,
  /// along its weakest_direction): there it takes the mean of the recent steps that were pinned at
  /// least this well (the last weak_step_window, time-scaled; at least 3 of them), the rest of the
  /// step and its turn kept. Where a match cannot see a direction its start stays, so repeating a
  /// step that was off along it repeats the error every sweep: in the simulated hand-held loops the
  /// drift ran 26-53 cm a sweep sideways for 7-14 sweeps in a row (docs/benchmarks.md, "Moving LiDAR").
  /// Not for keyframes without times: on the real hand-held keyframes (0.5 s apart, their
  /// predictions 30-60 cm off anyway) it helped nothing and ended 2 of 12 runs doubtful. 0: off.
  double weak_step_constraint = 0.1;
  int weak_step_window = 20;  ///< ...over the trusted steps into the last this many scans
  /// A timed sweep's match from its prediction, and its refinement after the deskew, hold the
  /// sensor to their start with a spring as strong as this many point pairs (IcpSettings::
  /// start_spring_pairs; translation only, point-to-point stages). Where the surfaces pin a
  /// direction, a sweep's thousands of pairs outweigh it; along one they hardly pin, it keeps the
  /// constant-velocity start where a few wrong pairs would slide the match sideways. The six
  /// simulated hand-held loops end 0.26-0.99 % off their paths with it, 0.46-2.80 % without
  /// (docs/benchmarks.md, "A spring for a narrow field"). 0: off.
  double sweep_start_spring_pairs = 160.0;
  /// ...at full weight while the recent predictions' translation error (PredictionError::
  /// translation_rms_cm, over at least confirm_min_history trusted matches) is at most this, and
  /// weaker with its square beyond (half the weight at 1.4 times it): a prediction that has been
  /// off by decimetres (a sensor turning fast, a corner taken at speed) holds a match no better.
  /// With fewer trusted matches behind it, none.
  double sweep_spring_full_error_cm = 4.0;
  /// ...and only on a sweep whose points span less than this many degrees of azimuth about the
  /// sensor (a narrow field, a rosette scanner's): it sees a corridor's walls only ahead, where they
  /// pin nothing along it, and slides. A spinning sensor sees the walls beside it, and what its
  /// prediction gets wrong is the turn in a corner, which a spring cannot mend. 360: every sweep.
  double sweep_spring_max_field_deg = 180.0;
  /// A held match that ended more than this from its prediction is matched again without the
  /// spring: where the two end apart (confirm_agree_cm / _deg), the surfaces measured a move the
  /// spring held short of (a change of speed) or a slide it saved. The scan's FPFH features decide:
  /// the one they agree with is kept; where they find nothing or agree with neither, the held one
  /// is kept and named doubtful (SurveyMatcher::release_held_match).
  double sprung_release_cm = 8.0;
  /// A timed sweep is doubtful when its match and those of the sweeps before it, each pinning its
  /// weakest turn less than unpinned_turn_constraint of its best (RegistrationHealth::
  /// rotation_constraint), turned the sensor by more than this in all (each sweep's turn counted
  /// whatever its sense) about those axes within the last unpinned_turn_window_s; those steps then
  /// lose their turns about those axes (SurveyMatcher::doubt_unpinned_turn). Surfaces that cannot
  /// see a turn do not measure one, yet a scanner whose pattern turns from sweep to sweep (a
  /// rosette's, 6 deg a sweep in the simulator) pulls its matches round with it: the simulated
  /// hand-held sensor standing still was turned 8-20 deg a sweep back and forth (136 deg in a
  /// second), walking at 0.5 m/s 7 deg a sweep for 12 sweeps (72), both with exit 0; walking at
  /// 1.4 m/s its matches turn 9-13 deg a second about that axis, as its sway does (8-9)
  /// (docs/benchmarks.md, "A turn the surfaces cannot pin"). 0: off.
  double max_unpinned_turn_deg = 30.0;
  double unpinned_turn_window_s = 1.0;
  /// ...a spinning sensor pins every turn at 0.4-0.5 of its best, a forward-looking one in a
  /// tunnel the turn about its view axis at 0.03-0.07.
  double unpinned_turn_constraint = 0.1;
  /// The first timed sweep, the survey's frame, is matched again once this many sweeps after it are
  /// registered: against them all (its deskew again by the step into sweep 1 as it then stands),
  /// and they are moved together, rigidly, to where that match puts them, the first sweep staying
  /// where it stands. Its first place came from one match, sweep 1's against it alone, and every
  /// later pose keeps that match's error as a turn of the whole map: on the simulated drives the
  /// first steps were 0.2-4.6 deg off (docs/benchmarks.md, "The first sweep matched again").
  /// 0: off.
  int first_sweep_rematch_scans = 20;
  /// ...and there its own motion over the sweep is fitted against them first (registration/
  /// sweep_fit.hpp), the deskew then by that motion: the step into sweep 1 says how the sensor moved
  /// after the first sweep, not during it. The simulated spinning loops start in a corner: their
  /// first sweep turned 43 deg, the step said 12-13, and the map kept 6 deg of it (docs/
  /// benchmarks.md, "The first sweep's own motion"). false: the step's motion, as for later sweeps.
  bool first_sweep_fit = true;
  /// The first sweep's fit; its pair bound is the matches' (MappingSettings::pairwise_icp).
  SweepFitSettings first_sweep_fit_settings;
  /// Where that fit was not kept (it did not converge, or the match from it was not trusted) and
  /// the step into sweep 1 turned the sensor more than this over one sweep, the first sweep is
  /// doubtful: deskewed by that step, its shape, and with it the frame of the whole map, may be off
  /// by part of the turn (the simulated spinning loop of seed 2: its first sweep turned 43 deg, the
  /// step said 12, and the map stood 2 % of its path off with exit 0 where a build's fit did not
  /// converge). The steps of the simulated drives turned 0.1-10 deg a sweep (docs/benchmarks.md,
  /// "A first sweep whose own motion was not fitted").
  double unfitted_first_sweep_max_turn_deg = 5.0;
  void validate() const;
  bool operator==(const MotionSettings&) const = default;
};

/// Recovery (slam/survey_matcher.cpp, match_scan): in a sequence without odometry, a scan whose
/// match from the motion model's start stays doubtful (or fails) is registered again without a
/// start: its features against those of the local map around the previous scan
/// (registration/global_registration.hpp), then matched from there as any scan, and kept when that
/// match is trusted. A car's scans 3-12 m and up to 40 degrees apart (KITTI 07) start out of ICP's
/// reach from constant velocity; a match that converged right from there anyway is confirmed by the
/// same pose from an independent start. Odometry's starts are left as they are: a doubtful match
/// there is the user's to see (docs/benchmarks.md).
struct RecoverySettings {
  bool enabled = true;
  GlobalRegistrationSettings global;
  /// The local map holds the registered scans' points within the scan's box, placed at the previous
  /// scan's pose, grown by this: how far a lost scan may have gone.
  double reach_cm = 1500.0;
  void validate() const;
  bool operator==(const RecoverySettings&) const = default;
};

/// Closing loops (pairwise and incremental matching; slam/loop_closing.cpp, slam/pose_graph.hpp).
/// After the last scan, a scan that stands near one at least min_scan_gap scans earlier is matched
/// against it; each trusted match is an edge of the scan graph, with the chain of matches from scan
/// to scan, and a global relaxation of the graph spreads what the loop measured over the whole
/// loop, as 3DTK's LUM does. While matching, the metascan then holds only the last min_scan_gap
/// scans, so a loop is closed by the relaxation, not by one scan's jump where the drive meets its
/// start.
struct LoopClosureSettings {
  bool enabled = true;
  int min_scan_gap = 12;             ///< a loop joins scans at least this many apart (48 m at 4 m steps)
  double max_distance_cm = 1000.0;   ///< candidates: scans whose positions are this close...
  /// ...with at least this much drive between them (along the scan positions): in a survey of
  /// scans half a metre apart, 12 scans back is still the same stretch of tunnel, not a loop.
  double min_path_cm = 4000.0;
  /// A return (scans in a row that all have a candidate) longer than this much drive is cut into
  /// returns of this length, one loop edge each (0: never cut). A patrol that passes the same loop
  /// lap after lap is one return from its second lap on: with one edge for all of it the laps drift
  /// apart between edges (4 laps of 120 m: 33 cm from the first lap, 8 cm cut every 100 m; 10 laps
  /// of 400 m: 50 and 6 cm; docs/scaling.md, "Loops at scale"). A return shorter than this (a
  /// survey's drive back to its start) keeps its one edge.
  double max_return_path_cm = 10000.0;
  /// The pair bounds a loop match tries, coarse to fine, until one is trusted: what has drifted
  /// further than this over the loop is not closed (and said so).
  std::vector<float> bound_factors = {1.0f, 4.0f, 16.0f};
  /// Each edge's information from its match's geometry (point-to-plane, on the planes of the scan it
  /// ends at: MappingSettings::plane_cell_cm), as LUM takes its covariances from the point pairs: the
  /// relaxation then bends a step along what its match could not see (a slide along a tunnel) rather
  /// than every step alike. Off: every edge has graph's sigmas, alike in every direction.
  bool information_from_geometry = true;
  /// Every direction keeps at least this fraction of graph's information, however blind its match.
  double min_information_fraction = 0.01;
  /// A closed loop whose gap before the relaxation is more than this fraction of the drive between
  /// its two scans makes the later scan doubtful: the chain was that far off, the relaxation only
  /// spread it (a 1 % misclosure is what the issue calls a map that is off; stop-and-go loops close
  /// at 0.06 %, docs/benchmarks.md). 0: never.
  double max_misclosure_fraction = 0.01;
  /// A loop match that turns its scan more than this many degrees per 100 m of drive between its
  /// two scans, from where the chain (and the loops closed before it) put the scan, is not an edge:
  /// no drift of the matches turns a map that fast, and a corridor seen the other way, or a
  /// look-alike place, fits as well as the right one (a simulated hand-held loop closed 54 deg
  /// off and 0.9 % apart: under the misclosure test, its map bent 1.9 % off; the right loops of the
  /// simulated drives turned at most 15 deg per 100 m, docs/benchmarks.md). 0: never.
  double max_turn_deg_per_100m = 30.0;
  /// After the relaxation every scan is judged again against the map near it: every scan whose box
  /// meets its own, earlier or later (0), or only the nearest this many. A survey that passes the
  /// same place lap after lap has every lap near each scan, and judging against all of them costs
  /// what the matching did several times over; the nearest few see less of the tunnel than the scan
  /// does, and judge more harshly (docs/scaling.md: 10 laps, 1000 scans, 384 s -> 39 s at 32, and
  /// one scan called doubtful that all the laps pass). So all, by default.
  int judge_max_scans = 0;
  /// ... and of at most this many visits to its place (0: all; a visit is a run of scans within
  /// min_scan_gap of each other, slam/local_map.hpp nearest_visits): the scan's own, the first, and
  /// the next nearest in the drive. Whole visits cover the tunnel the scan sees, and the first is
  /// what a loop closed to; a tenth lap is not judged against the nine before it (docs/scaling.md:
  /// 10 laps, 1000 scans). Places passed at most this often are judged against every scan near.
  int judge_max_visits = 3;
  /// A narrow-field timed sweep's loop match (a rosette scanner's: its points span less azimuth
  /// than MotionSettings::sweep_spring_max_field_deg, the spring's own test) is made against the
  /// sweeps within this many of the earlier one, before and after it (its visit), as one tree
  /// thinned as the local map is, not against that one sweep: one sweep of a forward-looking
  /// sensor's pattern sees too little of a place, and on three of six simulated hand-held loops
  /// no loop match found pairs ("too few pairs") where the visit closed each (docs/benchmarks.md,
  /// "A loop closed against the visit"). 0: the one sweep. A spinning sensor's sweeps see all
  /// around: theirs stays the one sweep.
  int visit_sweeps = 6;
  PoseGraphSettings graph;
  void validate() const;
  bool operator==(const LoopClosureSettings&) const = default;
};

/// Survey control (issue 29; slam/control_tie.hpp): the map tied to known points of the mine's grid.
struct ControlSettings {
  /// Hand back the survey's pose graph (MappingResult::graph: every scan's step as matched, with its
  /// match's information, and the closed loops' edges): what a tie to control adjusts. Costs one
  /// search a scan after the last (the steps' information); set by `--control`.
  bool keep_graph = false;
  /// A control point whose position, predicted by the map tied to the other points, lies farther
  /// from its known position than this many of the difference's sigmas (the point's and the map's
  /// together; the 3D Mahalanobis distance) is a blunder: left out, named, and its scan doubtful.
  /// 4.0 is chi-square's 99.9 % with 3 degrees of freedom (4.03 sigmas).
  double blunder_sigmas = 4.0;
  /// The map's sigmas (each scan's covariance from the pose graph) times this: the step information
  /// measures how well a match's geometry pins it, not the error it makes; the factor is calibrated
  /// against the simulated surveys' truth (docs/benchmarks.md, "Survey control").
  double sigma_scale = 0.65;
  /// Where the control points lie nearly in a line, the roll about it keeps the map's own vertical
  /// (the survey frame's up stays the grid's) to this sigma (slam/control_tie.cpp): a scanner on a
  /// mine floor stands within a few degrees of level.
  double level_sigma_deg = 2.0;
  void validate() const;
  bool operator==(const ControlSettings&) const = default;
};

/// Everything map_survey takes. MappingSettings{} is minemap's default, the whole-survey mode: each
/// scan, reduced to 15 cm voxel means, is matched once against the metascan of the registered scans
/// near it (10 cm voxel means), with default_icp() (25 cm, then 7.5 cm). simultaneous() is the
/// paper's queue-based relaxation on slice-filtered scans with minemap's ICP (the default before
/// 2026-12); paper() is the paper's method as published. The figures behind each choice, and
/// against 3DTK's slam6D, are in docs/benchmarks.md.
struct MappingSettings {
  MatchingMode mode = MatchingMode::kIncremental;
  bool filter_enabled = true;             ///< the slice filter (reduction kSlices, scans with slices)
  SliceFilterSettings filter;
  /// kVoxel reduces every scan, sliced or not, to voxel means (the slice filter does not apply).
  Reduction reduction = Reduction::kVoxel;
  float voxel_cm = 15.0f;                 ///< kVoxel: the data's voxel size
  /// kVoxel with dense_models: models are the voxel means at this finer size (0 or >= voxel_cm:
  /// the data clouds themselves).
  float model_voxel_cm = 10.0f;
  int unstructured_point_stride = 1;      ///< kSlices, scans without slices: keep every n-th point
  KdTreeSettings tree;
  IcpSettings icp = default_icp();
  /// Models (the scans a scan is matched *against*) may be denser than the data being matched, as
  /// in KISS-ICP's double downsampling: a pair then measures the distance to the other scan's
  /// surface rather than to its sampling, which removes much of point-to-point ICP's bias on
  /// reduced data. kVoxel: models are model_voxel_cm means. kSlices: a model keeps every
  /// `model_slice_stride`-th slice, filtered otherwise as `filter` says (scans without slices:
  /// every point). Off: models are the data clouds, as in the paper.
  bool dense_models = true;
  int model_slice_stride = 1;
  /// kIncremental: the metascan keeps the model points within the new scan's box (at its predicted
  /// pose) grown by the pair bound and this: the largest correction ICP is expected to make.
  double metascan_margin_cm = 200.0;
  /// The paper: scans overlap iff more than this many pairs (by default ICP's own minimum, 250).
  /// pairwise_icp() never asks for more pairs than this: a pair of scans that overlaps can be
  /// registered.
  int min_overlap_pairs = IcpTermination{}.min_pairs;
  /// ...but a scan with few points asks for at most this fraction of its data points (the 250 pairs
  /// were written for the paper's 80 000-point scans; a 5 000-point LiDAR keyframe reduces to about
  /// 1 500 voxel means). At least 3, Horn's minimum. The health check's paired fraction judges the
  /// rest.
  double min_overlap_fraction = 0.1;
  double moved_translation_cm = 5.0;      ///< step 3c: a match "moved" the scan beyond this...
  double moved_rotation_deg = 0.25;       ///< ...or this
  /// kSimultaneous, step 3: a scan is matched against the union of at most this many scans that
  /// overlap it, the nearest first (0: every one, as the paper). Where every scan sees every other
  /// (a hall, a handheld loop) the union, and the cost of each new scan, would grow with the survey.
  int max_relaxation_neighbours = 8;
  /// kSimultaneous, step 3: matches after one new scan. What is still queued then waits for the
  /// next scan (the queue persists, the new scan goes first), and after the last scan the queue is
  /// matched until it is empty or 2 x scans matches were made: the cost per new scan stays flat as
  /// the survey grows (docs/benchmarks.md, time per scan). 0: the queue is emptied after every scan,
  /// as the paper, with at most 4 x scans so far matches.
  int max_relaxation_matches_per_scan = 8;
  /// kSimultaneous, step 3: a relaxation match starts where its scan already sits, so it is
  /// converged once a step moves less than this and turns less than relaxation_min_step_deg: still
  /// well under the 1.5 cm range noise, with about half the iterations of ICP's own 0.01 cm /
  /// 0.001 deg at the same error (docs/benchmarks.md; 0.1 cm / 0.01 deg saved more and lost
  /// accuracy). 0: ICP's own thresholds, as paper() keeps (relaxation_icp()).
  double relaxation_min_step_cm = 0.03;
  double relaxation_min_step_deg = 0.003;
  /// Every match is judged (registration/health.hpp); a doubtful one is named in ScanOutcome::health.
  HealthSettings health;
  /// Each scan's surfaces are cut into cubes of this size, and a plane fitted in each (a normal):
  /// what the health's constraint test and the loop edges' information measure with.
  float plane_cell_cm = 50.0f;
  /// Pairwise and incremental matching: a doubtful match is tried again from the same start at these
  /// multiples of the pair bound, coarse to fine, until one is trusted (1 m, then 4 m for 25 cm):
  /// a start out of the 25 cm bound's reach (LiDAR without odometry) then still ends right, and
  /// a survey whose matches are all trusted pays nothing. Empty: no retries.
  std::vector<float> retry_bound_factors = {4.0f, 16.0f};
  /// No retry starts wider than this: at tens of metres every surface pairs with some other one. A
  /// rung beyond it is tried at it (once), so a bound of 2 m is retried at 4 m.
  float max_retry_bound_cm = 400.0f;
  LoopClosureSettings loops;
  MotionSettings motion;
  RecoverySettings recovery;
  ControlSettings control;

  /// The default preset's ICP: the paper's schedule, then a refinement at 7.5 cm (0.3 x 25 cm),
  /// Anderson-accelerated, a phase converged when a step moves less than 1 mm and turns less than
  /// 0.01 deg (1.7 mm at 10 m), well under the 1.5 cm range noise (docs/benchmarks.md: half the
  /// iterations on the default survey of ICP's own thresholds, the same error per step).
  static IcpSettings default_icp();
  /// The simultaneous preset's ICP: the paper's schedule, then a refinement at 10 cm (0.4 x 25 cm),
  /// Anderson-accelerated, with ICP's own convergence thresholds.
  static IcpSettings simultaneous_icp();
  /// The paper's simultaneous matching (queue-based relaxation) of slice-filtered scans against
  /// dense models, with simultaneous_icp().
  static MappingSettings simultaneous();
  /// The paper's method: simultaneous matching, slice filter, models reduced like the data, plain
  /// ICP at 25 cm (Table I's rows).
  static MappingSettings paper();
  static MappingSettings preset(Preset preset);

  /// What every match of a scan against others runs (steps 1 and 3, retries, loop matches and the
  /// health check's bound): `icp`, asking for no more pairs than the overlap test.
  IcpSettings pairwise_icp() const;
  /// The pairs a match of a scan with `data_points` reduced points needs: pairwise_icp()'s, or
  /// min_overlap_fraction of its points where that is fewer (at least 3).
  int min_pairs_for(std::size_t data_points) const;
  /// Step 3's matches: pairwise_icp() converged at relaxation_min_step_cm / _deg (where > 0).
  IcpSettings relaxation_icp() const;
  /// Whether scans keep a separate, denser model cloud of voxel means (kVoxel).
  bool voxel_models() const;
  /// Whether scans need their planes (the health's constraint test, loop edges' information).
  bool needs_planes() const;
  /// Throws std::invalid_argument naming the bad setting (map_survey calls it once, at entry).
  void validate() const;
  bool operator==(const MappingSettings&) const = default;
};

}  // namespace minemap
