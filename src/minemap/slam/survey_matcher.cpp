#include "minemap/slam/survey_matcher.hpp"

namespace minemap::detail {

SurveyMatcher::SurveyMatcher(const MappingSettings& settings, ComputeBackend& backend, RunControl control)
    : settings_(settings),
      backend_(backend),
      control_(std::move(control)),
      preparation_(settings, backend),
      local_map_(settings, backend),
      registration_(settings, backend),
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

MappingResult SurveyMatcher::run(const std::vector<Scan>& scans) {
  control_.expect(scans.size());
  std::vector<PreparedScan> prepared = preparation_.prepare_all(scans, control_);
  for (std::size_t i = 0; i < scans.size(); ++i) append(scans[i], std::move(prepared[i]));
  for (std::size_t i = 1; i < scans.size(); ++i) {
    if (control_.stop_requested()) {
      // Scans 0..i-1 are final (a relaxation cut short leaves them where its last match put them).
      interrupted_ = true;
      scans_matched_ = i;
      return result();
    }
    match_scan(i);
  }
  finish();
  return result();
}

void SurveyMatcher::add(const Scan& scan) {
  control_.expect(state_.size() + 1);
  append(scan, preparation_.prepare(scan, control_));
  if (state_.size() > 1) match_scan(state_.size() - 1);
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

Pose SurveyMatcher::predicted_start(std::size_t i) const {
  const Pose odometry_step = rigid_inverse(state_.odometry(i - 1)) * state_.odometry(i);
  return state_.pose(i - 1) * odometry_step;
}

ScanMatch SurveyMatcher::match_pairwise(std::size_t i, const Pose& start) const {
  const std::size_t previous[] = {i - 1};
  return registration_.register_scan(state_.prepared(i), start,
                                     [&](float, const Pose&) { return state_.models_of(previous); });
}

ScanMatch SurveyMatcher::match_incremental(std::size_t i, const Pose& start) const {
  // In the frame of scan i-1, so the metascan's float coordinates stay small wherever the survey
  // is; the metascans made for each bound live until the scan is registered.
  const Pose frame = state_.pose(i - 1);
  std::vector<std::shared_ptr<const PreparedCloud>> metascans;
  return registration_.register_scan(state_.prepared(i), start, [&](float bound_cm, const Pose& standing) {
    const double grow_cm = double(bound_cm) + settings_.metascan_margin_cm;
    metascans.push_back(local_map_.metascan(state_, i, standing, frame, start, grow_cm, LocalMap::Scope::kEarlier));
    return std::vector<WorldModel>{{metascans.back().get(), frame}};
  });
}

void SurveyMatcher::relax(std::size_t newest, int budget) {
  const Relaxation::Tally tally = relaxation_.relax(state_, newest, budget, control_);
  relaxation_matches_ += tally.matches;
  step3_iterations_ += tally.iterations;
}

void SurveyMatcher::match_scan(std::size_t i) {
  const RunControl::Stopwatch arrived;
  control_.timed(&StageTimes::pairwise_s, [&] {
    const Pose start = predicted_start(i);
    const ScanMatch match =
        settings_.mode == MatchingMode::kIncremental ? match_incremental(i, start) : match_pairwise(i, start);
    step1_iterations_ += match.iterations;
    if (!match.ok()) {
      state_.fail(i, start, match.first);
      return;
    }
    state_.place(i, match.first.world_from_data, match.first);
    if (match.retry) state_.place(i, match.retry->world_from_data, *match.retry);
    state_.judged(i, match.health);
  });
  if (settings_.mode == MatchingMode::kSimultaneous) {
    control_.timed(&StageTimes::relaxation_s, [&] {
      relaxation_.queue_first(i);  // step 2: the new scan first
      const int per_scan = settings_.max_relaxation_matches_per_scan;
      relax(i, per_scan > 0 ? per_scan : 4 * static_cast<int>(i + 1));
    });
  }
  state_.set_match_time(i, arrived.seconds());
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
      std::vector<LoopClosure> closed = loop_closing_.close(state_, control_);
      loops_.insert(loops_.end(), closed.begin(), closed.end());
    });
  }
  interrupted_ = false;
  scans_matched_ = n;
}

MappingResult SurveyMatcher::result() const {
  MappingResult result;
  result.scans = state_.outcomes();
  result.backend = backend_name_;
  result.notes = notes_;
  result.times = control_.times();
  result.step1_icp_iterations = step1_iterations_;
  result.step3_icp_iterations = step3_iterations_;
  result.relaxation_matches = relaxation_matches_;
  result.loops = loops_;
  result.interrupted = interrupted_;
  result.scans_matched = scans_matched_;
  return result;
}

}  // namespace minemap::detail
