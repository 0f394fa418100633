#include "minemap/slam/survey_matcher.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <span>

#include <tbb/task_arena.h>

#include "minemap/core/memory.hpp"

namespace minemap::detail {

SurveyMatcher::SurveyMatcher(const MappingSettings& settings, ComputeBackend& backend, RunControl control)
    : settings_(settings),
      backend_(backend),
      control_(std::move(control)),
      preparation_(settings, backend),
      local_map_(settings, backend),
      motion_(settings),
      registration_(settings, backend),
      recovery_(settings, local_map_),
      relaxation_(settings, backend, registration_, local_map_),
      loop_closing_(settings, backend, registration_, local_map_),
      backend_name_(backend.name() + ": " + backend.device_description()) {}

void SurveyMatcher::append(const Scan& scan, PreparedScan prepared) {
  state_.add(scan, std::move(prepared));
  if (preparation_.skipped_slice_filter() && !noted_unstructured_) {
    notes_.push_back("scans without slice structure: slice filter skipped");
    noted_unstructured_ = true;
  }
}

namespace {

/// Frees a scan's points and attributes (swapped out: clear() keeps the capacity).
void release_points(Scan& scan) {
  std::vector<Eigen::Vector3f>().swap(scan.points_cm);
  std::vector<std::uint32_t>().swap(scan.slice_offsets);
  scan.attributes = {};
}

}  // namespace

MappingResult SurveyMatcher::run(const std::vector<Scan>& scans, std::vector<Scan>* release) {
  control_.expect(scans.size());
  // A chunk at a time, as add_part takes a survey's parts: its reduced clouds and its raw points
  // are not all held at once (the voxel means in parallel within the chunk; the same result).
  const std::size_t chunk = 4 * static_cast<std::size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  for (std::size_t first = 0; first < scans.size(); first += chunk) {
    const std::size_t count = std::min(chunk, scans.size() - first);
    const std::span<Scan> owned = release != nullptr ? std::span<Scan>(release->data() + first, count) : std::span<Scan>{};
    if (!take_part({scans.data() + first, count}, owned)) return result();
  }
  finish();
  return result();
}

void SurveyMatcher::bound_memory(const std::filesystem::path& spill_folder, std::size_t held_bytes) {
  state_.bound_memory(std::make_shared<ScanSpill>(spill_folder, settings_, backend_), held_bytes);
}

bool SurveyMatcher::add_part(std::vector<Scan>& part, std::size_t total) {
  control_.expect(total);
  return take_part(part, part);
}

bool SurveyMatcher::take_part(std::span<const Scan> part, std::span<Scan> owned) {
  const std::size_t first = state_.size();
  const auto release = [&](std::size_t k) {
    if (!owned.empty()) release_points(owned[k]);
  };
  const auto stop_before = [&](std::size_t i) {
    // Scans 0..i-1 are final (a relaxation cut short leaves them where its last match put them).
    if (i == 0 || !control_.stop_requested()) return false;
    interrupted_ = true;
    scans_matched_ = i;
    return true;
  };
  const bool sweeps = std::any_of(part.begin(), part.end(), [&](const Scan& scan) {
    return settings_.motion.deskew != DeskewMode::kOff && !scan.attributes.time_s.empty();
  });
  if (sweeps) {
    // A moving sensor's sweeps: each is deskewed by the motion before it, so each is prepared as it
    // arrives, as `add` does.
    for (std::size_t k = 0; k < part.size(); ++k) {
      if (stop_before(first + k)) return false;
      arrive(part[k]);
      release(k);
      state_.release_over_budget();
    }
    return true;
  }
  // The part's voxel means in parallel; its progress is the matching's alone (the reduction and the
  // matching take turns part by part).
  std::vector<PreparedScan> prepared = preparation_.prepare_all(part, control_);
  for (std::size_t k = 0; k < part.size(); ++k) {
    append(part[k], std::move(prepared[k]));
    release(k);
  }
  for (std::size_t i = std::max<std::size_t>(first, 1); i < state_.size(); ++i) {
    if (stop_before(i)) return false;
    match_scan(i);
    state_.release_over_budget();
  }
  return true;
}

void SurveyMatcher::add(const Scan& scan) {
  control_.expect(state_.size() + 1);
  arrive(scan);
}

void SurveyMatcher::arrive(const Scan& scan) {
  const SweepTiming timing = preparation_.timing_of(scan);
  if (timing.empty()) {
    append(scan, preparation_.prepare(scan, control_));
    if (state_.size() > 1) match_scan(state_.size() - 1);
    return;
  }
  // In the state first (its pose and stamp), so the motion model can predict it; then prepared.
  const std::size_t i = state_.size();
  PreparedScan stamped;
  stamped.stamp_s = timing.stamp_s;
  stamped.sweep_s = timing.duration_s;
  append(scan, std::move(stamped));
  std::optional<Pose> sweep_motion;
  if (i >= 2 && state_.registered(i - 1)) {
    sweep_motion = motion_.sweep_motion(state_, i, motion_.predict(state_, i).start, i - 1);
  }
  state_.set_prepared(i, preparation_.prepare(scan, control_, timing, sweep_motion));
  if (i == 0) {
    first_sweep_ = scan;
    return;
  }
  match_scan(i, &scan, &timing);
}

void SurveyMatcher::restore(const Scan& scan, const ScanOutcome& outcome) {
  control_.expect(state_.size() + 1);
  append(scan, preparation_.prepare(scan, control_));
  state_.restore(state_.size() - 1, outcome);
}

void SurveyMatcher::restore_counters(const MappingResult& saved) {
  step1_iterations_ = saved.step1_icp_iterations;
  step3_iterations_ = saved.step3_icp_iterations;
  relaxation_matches_ = saved.relaxation_matches;
  notes_ = saved.notes;
  control_.times() = saved.times;
}

ScanMatch SurveyMatcher::match_pairwise(std::size_t i, const Pose& start, float start_bound_cm,
                                        Convergence convergence, const MatchObjectives& objectives) const {
  const std::size_t previous[] = {i - 1};
  return registration_.register_scan(
      state_.prepared(i), start, [&](float, const Pose&) { return state_.models_of(previous); }, start_bound_cm,
      convergence, objectives);
}

ScanMatch SurveyMatcher::match_incremental(std::size_t i, const Pose& start, float start_bound_cm,
                                           Convergence convergence, const MatchObjectives& objectives) const {
  // In the frame of scan i-1, so the metascan's float coordinates stay small wherever the survey
  // is; the metascans made for each bound live until the scan is registered.
  const Pose frame = state_.pose(i - 1);
  const PreparedScan& scan = state_.prepared(i);
  const double thin_cm = motion_.local_map_cell_cm(state_, i);
  const PreparedCloud& own = *scan.cloud;
  const double radius_cm = std::max(own.bounds_min().norm(), own.bounds_max().norm());
  // How far the scan's box moves between two poses: the sensor's move and its turn at the box's edge.
  const auto box_shift_cm = [&](const Pose& from, const Pose& to) {
    const Pose moved = rigid_inverse(from) * to;
    return translation_norm(moved) + rotation_angle_deg(moved) * (M_PI / 180.0) * radius_cm;
  };
  // A wide-field timed sweep's metascan serves the sweeps after it too (MotionSettings::
  // local_map_sweeps), grown by how far their boxes are expected to move: the last step's shift,
  // once more for each. A narrow field's newest sweep is the only one that saw what lies ahead.
  const MotionSettings& motion = settings_.motion;
  const int serves = thin_cm > 0.0 && scan.sweep_s > 0.0 && motion.local_map_sweeps > 1 &&
                             !narrow_field(state_, i, motion.sweep_spring_max_field_deg)
                         ? motion.local_map_sweeps
                         : 1;
  const double ahead_cm = serves > 1 && i >= 2 ? kLocalMapShiftAllowance * double(serves - 1) *
                                                     box_shift_cm(state_.pose(i - 2), state_.pose(i - 1))
                                               : 0.0;
  std::vector<std::shared_ptr<const PreparedCloud>> metascans;
  return registration_.register_scan(scan, start, [&](float bound_cm, const Pose& standing) {
    LastMetascan& last = last_metascan_;
    // A metascan serving several sweeps serves any bound up to its own (its crop holds theirs).
    const bool bound_served = serves > 1 ? last.bound_cm >= bound_cm : last.bound_cm == bound_cm;
    const bool same_match = last.cloud && last.scan == i && bound_served && last.frame == frame;
    const bool kept_from_before = last.cloud && last.scan < i && last.scan + std::size_t(serves) > i &&
                                  bound_served && last.older_moves == state_.older_moves();
    if (thin_cm > 0.0 && (same_match || kept_from_before) && standing == start) {
      // Half the margin is left for the match's correction; the rest, and the growth ahead, for the move.
      if (box_shift_cm(last.at, start) < 0.5 * settings_.metascan_margin_cm + last.ahead_cm) {
        return std::vector<WorldModel>{{last.cloud.get(), last.frame}};
      }
    }
    const double grow_cm = double(bound_cm) + settings_.metascan_margin_cm + (standing == start ? ahead_cm : 0.0);
    metascans.push_back(
        local_map_.metascan(state_, i, standing, frame, start, grow_cm, thin_cm));
    if (thin_cm > 0.0 && standing == start) {
      last = {i, bound_cm, frame, start, metascans.back(), ahead_cm, state_.older_moves()};
    }
    return std::vector<WorldModel>{{metascans.back().get(), frame}};
  }, start_bound_cm, convergence, objectives);
}

ScanMatch SurveyMatcher::match_from(std::size_t i, const Prediction& prediction, Convergence convergence) const {
  return settings_.mode == MatchingMode::kIncremental
             ? match_incremental(i, prediction.start, prediction.start_bound_cm, convergence,
                                 prediction.objectives)
             : match_pairwise(i, prediction.start, prediction.start_bound_cm, convergence,
                              prediction.objectives);
}

void SurveyMatcher::place(std::size_t i, const ScanMatch& match, const Pose& start) {
  if (!match.ok()) {
    state_.fail(i, start, match.first);
    return;
  }
  state_.place(i, match.first.world_from_data, match.first);
  if (match.retry) state_.place(i, match.retry->world_from_data, *match.retry);
  state_.judged(i, match.health);
}

void SurveyMatcher::relax(std::size_t newest, int budget) {
  const Relaxation::Tally tally = relaxation_.relax(state_, newest, budget, control_);
  relaxation_matches_ += tally.matches;
  step3_iterations_ += tally.iterations;
}

void SurveyMatcher::match_scan(std::size_t i, const Scan* raw, const SweepTiming* timing) {
  const RunControl::Stopwatch arrived;
  control_.timed(&StageTimes::pairwise_s, [&] {
    const Prediction prediction = motion_.predict(state_, i);
    // A sweep's first matches need only tell its deskew the step; the refinement matches again.
    const Convergence convergence = raw != nullptr && settings_.motion.provisional()
                                        ? Convergence::kProvisional
                                        : Convergence::kFinal;
    ScanMatch match = match_from(i, prediction, convergence);
    step1_iterations_ += match.iterations;
    release_held_match(i, prediction, match, convergence);
    confirm_far_match(i, prediction, match, convergence);
    Pose start = prediction.start;
    recover(i, prediction, match, start, convergence);
    prefer_prediction_along_slide(i, prediction, match, convergence);
    place(i, match, start);
    if (raw != nullptr && timing != nullptr) refine_deskew(i, *raw, *timing, convergence);
    doubt_unpinned_turn(i);
    if (raw != nullptr) rematch_first_sweep(i);
  });
  if (settings_.mode == MatchingMode::kSimultaneous) {
    control_.timed(&StageTimes::relaxation_s, [&] {
      relaxation_.queue_first(i);  // step 2: the new scan first
      const int per_scan = settings_.max_relaxation_matches_per_scan;
      relax(i, per_scan > 0 ? per_scan : 4 * static_cast<int>(i + 1));
    });
  }
  if (settings_.motion.local_map_sweeps <= 1) last_metascan_ = {};  // else kept for the sweeps after it
  features_start_.reset();
  features_said_ = false;
  state_.set_match_cost(i, arrived.seconds(), resident_bytes());
  control_.report(i + 1, to_string(settings_.mode));
}

void SurveyMatcher::finish() {
  const std::size_t n = state_.size();
  const bool simultaneous = settings_.mode == MatchingMode::kSimultaneous;
  if (simultaneous && !control_.stop_requested() && !relaxation_.empty()) {
    // What the per-scan budget left: matched now, at most 2 per scan.
    control_.timed(&StageTimes::relaxation_s, [&] { relax(n - 1, 2 * static_cast<int>(n)); });
  }
  if (simultaneous && control_.stop_requested()) {  // the last relaxation cut short
    interrupted_ = true;
    scans_matched_ = n;
    return;
  }
  if (settings_.loops.enabled && !simultaneous) {
    control_.timed(&StageTimes::loop_closure_s, [&] {
      std::vector<LoopClosure> closed = loop_closing_.close(state_, control_, &graph_);
      loops_.insert(loops_.end(), closed.begin(), closed.end());
    });
  }
  // A tie to control adjusts the survey's graph (slam/control_tie.hpp): the chain's steps as matched
  // (before any loop's relaxation moved them) and the loops' edges; without a loop, the chain now.
  if (settings_.control.keep_graph && graph_.empty() && !control_.stop_requested()) {
    control_.timed(&StageTimes::loop_closure_s, [&] {
      graph_ = control_.timed(&StageTimes::loop_graph_steps_s, [&] { return loop_closing_.chain(state_, control_); });
    });
  }
  interrupted_ = false;
  scans_matched_ = n;
}

MappingResult SurveyMatcher::result() const {
  MappingResult result;
  result.scans = state_.outcomes();
  result.spilled = state_.spilled();
  result.spilled_bytes = state_.spilled_bytes();
  result.backend = backend_name_;
  result.notes = notes_;
  result.times = control_.times();
  result.step1_icp_iterations = step1_iterations_;
  result.step3_icp_iterations = step3_iterations_;
  result.relaxation_matches = relaxation_matches_;
  result.loops = loops_;
  result.graph = graph_;
  result.interrupted = interrupted_;
  result.scans_matched = scans_matched_;
  return result;
}

}  // namespace minemap::detail
