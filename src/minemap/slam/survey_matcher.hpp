#pragma once
// Internal (not installed). The schedule of a mapping run, and nothing else: scans arrive (add, or
// all at once in run), each starts where the mode predicts it and is matched (match_scan), and the
// run is finished (the rest of the relaxation queue, then loops). A moving sensor's sweep is
// deskewed again by its match and matched again (refine_deskew), doubted where recent sweeps turned
// about axes their surfaces cannot pin (doubt_unpinned_turn), and the first sweep, the survey's
// frame, is matched again once the sweeps after it are in (rematch_first_sweep): those three in
// sweep_matching.cpp. A match that went far is checked from a second start before it is trusted
// (confirm_far_match, release_held_match, prefer_prediction_along_slide, recover): those in
// second_starts.cpp. The stages it calls:
//   scan_preparation   reduce one scan, build its trees (paper IV.C)
//   survey_state       where every scan stands; the one writer of poses
//   local_map          the metascan, and the relaxation's union
//   scan_registration  register and judge one scan, retry wider (paper IV.A, registration/)
//   recovery           a lost scan found again without a start (features and RANSAC)
//   relaxation         the paper's queue (IV.B step 3)
//   loop_closing       returns to known places and the pose graph
//
// Thread-safety: one thread at a time. A BackendError propagates (map_survey starts a fresh matcher
// on a CPU backend); nothing here is reset by hand.
#include <filesystem>
#include <optional>
#include <string>
#include <span>
#include <utility>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/registration/sweep_fit.hpp"
#include "minemap/slam/local_map.hpp"
#include "minemap/slam/loop_closing.hpp"
#include "minemap/slam/motion_model.hpp"
#include "minemap/slam/recovery.hpp"
#include "minemap/slam/relaxation.hpp"
#include "minemap/slam/run_control.hpp"
#include "minemap/slam/scan_preparation.hpp"
#include "minemap/slam/scan_registration.hpp"
#include "minemap/slam/survey_state.hpp"

namespace minemap::detail {

class SurveyMatcher {
 public:
  /// `settings` must outlive the matcher (and be valid: MappingSettings::validate).
  SurveyMatcher(const MappingSettings& settings, ComputeBackend& backend, RunControl control);

  /// map_survey: the scans prepared a chunk at a time (in parallel within it), then matched in
  /// order, then finished. `release` (the same scans, when the caller lets them go): each scan's
  /// points and attributes are freed once it is prepared (a sweep's once it is matched); its name,
  /// source and pose stay. The result is the same either way.
  MappingResult run(const std::vector<Scan>& scans, std::vector<Scan>* release = nullptr);
  /// PartwiseMapper::add: the next part of a survey (`total` scans in all), prepared (in parallel)
  /// and matched, each scan's points freed once prepared (a sweep's once matched). false: a stop was
  /// requested; the scans before it are final (result() says so), and no part should follow.
  bool add_part(std::vector<Scan>& part, std::size_t total);
  /// Before the first scan: hold at most `held_bytes` of prepared clouds, the rest in a spill file
  /// in `spill_folder` (SurveyState::bound_memory; the CPU backend only). The same result.
  void bound_memory(const std::filesystem::path& spill_folder, std::size_t held_bytes);
  /// LiveMapper::add: one more scan, prepared alone (the same clouds as run's), then matched.
  void add(const Scan& scan);
  /// LiveMapper::restore: one more scan prepared, its outcome as a previous run left it.
  void restore(const Scan& scan, const ScanOutcome& outcome);
  /// A resume: the previous run's counters (iterations, matches, notes, times).
  void restore_counters(const MappingResult& saved);
  void restore_queue(const std::vector<std::size_t>& queue) { relaxation_.restore_queue(queue, state_.size()); }
  /// What follows the last scan: the rest of the relaxation queue, then loop closing.
  void finish();

  /// The run so far, built from the state.
  MappingResult result() const;
  std::vector<std::size_t> queue() const { return relaxation_.queue(); }
  std::size_t size() const { return state_.size(); }
  const ScanOutcome& scan(std::size_t i) const { return state_.outcome(i); }

 private:
  /// Appends a prepared scan (and the note a skipped slice filter asks for).
  void append(const Scan& scan, PreparedScan prepared);
  /// One scan arrives (run's sweeps, and add): prepared (a sweep deskewed by the motion predicted
  /// for it) and matched.
  void arrive(const Scan& scan);
  /// run's chunks and add_part's parts: prepared and matched in order (a sweep as it arrives);
  /// `owned` (the same scans, or empty) has each scan's points freed once they are used. false: stopped.
  bool take_part(std::span<const Scan> part, std::span<Scan> owned);
  /// Scan i, arrived: the mode's match from where the motion model predicts it (a sweep's deskew
  /// refined by its registered step), and for kSimultaneous the relaxation after it (steps 2 and 3,
  /// within the per-scan budget). `raw`: the sweep itself, to deskew again.
  void match_scan(std::size_t i, const Scan* raw = nullptr, const SweepTiming* timing = nullptr);
  /// Step 1 (and the pairwise mode): scan i against scan i-1. Incremental: against the metascan.
  /// `convergence`: provisional for a sweep's matches before its deskew is refined.
  ScanMatch match_pairwise(std::size_t i, const Pose& start, float start_bound_cm, Convergence convergence,
                           const MatchObjectives& objectives) const;
  ScanMatch match_incremental(std::size_t i, const Pose& start, float start_bound_cm, Convergence convergence,
                              const MatchObjectives& objectives) const;
  ScanMatch match_from(std::size_t i, const Prediction& prediction,
                       Convergence convergence = Convergence::kFinal) const;
  /// A retry that landed far from the prediction, or a constant-velocity match that moved the sensor
  /// far from it (MotionSettings::confirm_sigmas): matched again from another start (where the
  /// scan's features put it, in a sequence without odometry; else the other model's); kept only
  /// when both end at the same pose (not when the only other start lies within the match's reach
  /// of the prediction: not independent). Else a jump's second match is kept where it ends near the
  /// prediction, trusted; otherwise keep_first_match.
  void confirm_far_match(std::size_t i, const Prediction& prediction, ScanMatch& match, Convergence convergence);
  /// A far retry that no second start confirmed is not kept: the scan stays where its first match
  /// put it, near a prediction that has been right lately, doubtful with that match's own doubt and
  /// the refuted retry (`refuted`) said after it. A corridor's walls fit as well metres along it: a
  /// 10-lap patrol kept such a retry's 4.8 m slip, and every lap after it stood 4.8 m off. A judging
  /// against more of the map (after a loop) may answer the first match's doubt. A first match that
  /// jumped (no retry) stays where it is, doubtful (the reach test), with `refuted` said.
  static void keep_first_match(ScanMatch& match, const char* refuted);
  /// How far a match that replaces the first one (from a second start) is from the prediction:
  /// its health's correction_cm / _deg and moved_cm, measured from `prediction.start` (the adaptive
  /// bound and the jump test learn from them), not from the second match's own start.
  void measure_from_prediction(std::size_t i, const Prediction& prediction, ScanMatch& match) const;
  /// Scan i's match from the prediction failed or is doubtful (MappingSettings::recovery): it is
  /// registered again without a start and matched from there. Where both matches end at one pose
  /// and each doubt was one a start can cause (reach, surfaces apart, not settled), it is trusted.
  /// A constant-velocity start's `match` and `start` are replaced when the new match is trusted; an
  /// odometry start's pose is kept. A doubt says what was tried when it stays.
  void recover(std::size_t i, const Prediction& prediction, ScanMatch& match, Pose& start, Convergence convergence);
  /// A constant-velocity match that its surfaces pin only weakly along one direction
  /// (MotionSettings::slide_constraint) and that moved the scan along it more than the pair bound
  /// from the prediction: matched again from the prediction with that move taken out (the rest of
  /// its correction kept), at the pair bound. A narrow-field hand-held sensor in a corridor slides
  /// metres along it from a wide first match, and is trusted there. The second is kept when
  /// trusted, nearer the prediction along that direction, and a clearly closer fit (its pairs' RMS
  /// under MotionSettings::slide_rms_factor of the first's); its note says so. A second match not
  /// kept changes nothing.
  void prefer_prediction_along_slide(std::size_t i, const Prediction& prediction, ScanMatch& match,
                                     Convergence convergence);
  /// A match held by the spring to its prediction (MatchObjectives::start_spring_pairs) that still
  /// ended more than MotionSettings::sprung_release_cm from it: matched again without the spring.
  /// Where the two end apart, a match from the scan's FPFH features decides: agreeing with the free
  /// one, that is kept (a change of speed the spring held short, with a note); agreeing with the
  /// held one, it stays; else the held one stays, doubtful, its doubt naming both.
  void release_held_match(std::size_t i, const Prediction& prediction, ScanMatch& match, Convergence convergence);
  /// Whether two matches of one scan, ending at `a` and `b`, agree: within
  /// MotionSettings::confirm_agree_cm and confirm_agree_deg of each other. The one test of
  /// agreement between two starts (confirm_far_match, release_held_match, recover).
  bool agree(const Pose& a, const Pose& b) const;
  /// Adds `text` to a match's note, after what it says already (each step that kept or confirmed
  /// a match says how, and a later step does not erase an earlier one's word).
  static void add_note(RegistrationHealth& health, const std::string& text);
  /// Whether scan i may be recovered: recovery on, scan i-1 registered.
  bool recovery_on(std::size_t i) const;
  /// Where scan i's features put it (Recovery::find), computed once per scan.
  const RecoveredStart& features_start(std::size_t i);
  /// Places scan i where `match` put it (or fails it at `start`).
  void place(std::size_t i, const ScanMatch& match, const Pose& start);
  /// A sweep registered: deskewed again by the step its match found, and matched again from there
  /// where that moved it (kept when no worse); a provisional match is matched again in any case.
  /// Scan 1 first deskews scan 0, by the same step.
  void refine_deskew(std::size_t i, const Scan& raw, const SweepTiming& timing, Convergence convergence);
  /// A timed sweep registered and judged: doubtful when it and the sweeps before it turned more
  /// than MotionSettings::max_unpinned_turn_deg about axes their surfaces hardly pin
  /// (MotionPrediction::unpinned_turn). The scan is named, and its step loses its turn about its
  /// weakest axis (the rest of its match stays).
  void doubt_unpinned_turn(std::size_t i);
  /// Scan i registered: where it is the MotionSettings::first_sweep_rematch_scans-th sweep, the
  /// first sweep is matched again against sweeps 1..i (one tree over their model points), and
  /// sweeps 1..i move rigidly to where each trusted match puts them. Scan 0 stays. Its deskew: its
  /// own motion fitted against them (fit_first_sweep), matched once from the fit's pose; where that
  /// fit or its match fails, the step into sweep 1 as it stands, up to kFirstSweepRounds times while
  /// the match moves them. A note says which.
  void rematch_first_sweep(std::size_t i);
  static constexpr int kFirstSweepRounds = 3;
  /// The first sweep's pose and motion over the sweep fitted against `later` (the union of the
  /// sweeps after it, placed at `frame`) from scan 0's pose and `step_motion`
  /// (registration/sweep_fit.hpp): nullopt where MotionSettings::first_sweep_fit is off or the
  /// sweep has no times; a fit that did not converge (or settle) is not used (a note says so).
  std::optional<SweepFit> fit_first_sweep(const Scan& first, const SweepTiming& timing, const PreparedCloud& later,
                                          const Pose& frame, const Pose& step_motion);
  /// Where the first sweep's fit was tried and not kept, and the step into sweep 1 (`step_motion`)
  /// turned more than MotionSettings::unfitted_first_sweep_max_turn_deg: scan 0 is judged doubtful
  /// with `health` (its last match against the `later` sweeps after it; not judged: none made),
  /// naming the turn. The poses stay.
  void doubt_unfitted_first_sweep(const std::optional<SweepFit>& fit, bool fit_kept, const Pose& step_motion,
                                  std::size_t later, RegistrationHealth health);
  void relax(std::size_t newest, int budget);

  const MappingSettings& settings_;
  ComputeBackend& backend_;
  RunControl control_;
  ScanPreparation preparation_;
  SurveyState state_;
  LocalMap local_map_;
  MotionPrediction motion_;
  ScanRegistration registration_;
  Recovery recovery_;
  Relaxation relaxation_;
  LoopClosing loop_closing_;
  // Counters of the run (MappingResult's).
  std::string backend_name_;
  std::vector<std::string> notes_;
  int step1_iterations_ = 0, step3_iterations_ = 0, relaxation_matches_ = 0;
  std::vector<LoopClosure> loops_;
  std::vector<PoseGraphEdge> graph_;  ///< ControlSettings::keep_graph: the survey's pose graph
  bool interrupted_ = false;
  std::size_t scans_matched_ = 0;
  bool noted_unstructured_ = false;
  /// The first sweep as read, kept until scan 1 is registered (then the step between them says how
  /// to deskew it) and, where it is matched again (MotionSettings::first_sweep_rematch_scans),
  /// until then.
  std::optional<Scan> first_sweep_;
  /// The metascan scan i's last incremental match took, at one bound: a sweep's second match
  /// (refine_deskew), from a pose a few centimetres from the first's start, takes the same one when
  /// the scan's box moved less than half the metascan's margin (metascan_margin_cm), instead of a
  /// new tree. A wide-field sweep's serves the sweep after it too (MotionSettings::local_map_sweeps:
  /// grown by ahead_cm, kept while none of its scans moved); otherwise dropped when the scan is done.
  struct LastMetascan {
    std::size_t scan = 0;
    float bound_cm = 0.0f;
    Pose frame = Pose::Identity(), at = Pose::Identity();
    std::shared_ptr<const PreparedCloud> cloud;
    double ahead_cm = 0.0;  ///< grown by this for the sweeps after scan (MotionSettings::local_map_sweeps)
    std::uint64_t older_moves = 0;  ///< SurveyState::older_moves when built: its scans as they stood
  };
  /// A metascan kept for the sweeps after its own is grown by this many times their expected shift.
  static constexpr double kLocalMapShiftAllowance = 1.5;
  mutable LastMetascan last_metascan_;
  /// features_start's answer for the scan being matched (dropped when it is done).
  std::optional<std::pair<std::size_t, RecoveredStart>> features_start_;
  /// A doubt of the scan being matched already says that its features found no start.
  bool features_said_ = false;
};

}  // namespace minemap::detail
