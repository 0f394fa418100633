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
  std::vector<std::shared_ptr<const PreparedCloud>> metascans;
  return registration_.register_scan(scan, start, [&](float bound_cm, const Pose& standing) {
    LastMetascan& last = last_metascan_;
    const bool same_match = last.cloud && last.scan == i && last.bound_cm == bound_cm && last.frame == frame;
    if (thin_cm > 0.0 && same_match && standing == start) {
      const PreparedCloud& own = *scan.cloud;
      const double radius_cm = std::max(own.bounds_min().norm(), own.bounds_max().norm());
      const Pose moved = rigid_inverse(last.at) * start;
      const double shift_cm = translation_norm(moved) + rotation_angle_deg(moved) * (M_PI / 180.0) * radius_cm;
      if (shift_cm < 0.5 * settings_.metascan_margin_cm) return std::vector<WorldModel>{{last.cloud.get(), frame}};
    }
    const double grow_cm = double(bound_cm) + settings_.metascan_margin_cm;
    metascans.push_back(
        local_map_.metascan(state_, i, standing, frame, start, grow_cm, thin_cm));
    if (thin_cm > 0.0 && standing == start) last = {i, bound_cm, frame, start, metascans.back()};
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

void SurveyMatcher::confirm_far_match(std::size_t i, const Prediction& prediction, ScanMatch& match,
                                      Convergence convergence) {
  const MotionSettings& motion = settings_.motion;
  if (!match.ok() || match.health.doubtful()) return;
  const PredictionError recent = motion_.recent_error(state_, i);
  if (recent.count < motion.confirm_min_history) return;
  const double bound_cm = settings_.icp.max_pair_dist_cm;
  const double far_cm = std::max<double>(motion.confirm_sigmas * recent.rms_cm, bound_cm);
  const bool far_retry = match.retry && match.health.moved_cm > far_cm;
  // A constant-velocity match whose sensor ended far from where the motion had it go: a wide first
  // match (the adaptive bound) slides along a corridor as a retry does (a real building walk: 3 m
  // where the true step was 10 cm, trusted), and the next prediction repeats the slide.
  const double jump_cm = std::max<double>(motion.confirm_sigmas * recent.translation_rms_cm, bound_cm);
  const bool jumped = !far_retry && prediction.constant_velocity && match.health.correction_cm > jump_cm;
  if (!far_retry && !jumped) return;
  const float reach_cm = match.retry ? match.health.retry_bound_cm : prediction.start_bound_cm;
  // The second start: where the scan's features put it (independent of any motion model), in a
  // sequence without odometry where recovery is on and they find it; else the other model's.
  Prediction other;
  other.objectives.fine = motion_.fine_objective(state_, i);
  const RecoveredStart* features =
      recovery_on(i) && motion_.constant_velocity_at(state_, i) ? &features_start(i) : nullptr;
  const bool from_features = features != nullptr && features->global.found;
  if (from_features) {
    other.start = features->start;
  } else {
    other.start = motion_.alternative_start(state_, i);
    other.start_bound_cm = reach_cm;
  }
  char text[480];
  char what[200];
  if (far_retry) {
    std::snprintf(what, sizeof what, "the %g cm retry moved its points %.0f cm, %.0f times the recent predictions' error (%.1f cm RMS)",
                  double(match.health.retry_bound_cm), match.health.moved_cm, match.health.moved_cm / recent.rms_cm,
                  recent.rms_cm);
  } else {
    std::snprintf(what, sizeof what, "the match moved the sensor %.0f cm from the prediction, %.0f times the recent predictions' (%.1f cm RMS)",
                  match.health.correction_cm, match.health.correction_cm / std::max(recent.translation_rms_cm, 1e-3),
                  recent.translation_rms_cm);
  }
  const PreparedScan& scan = state_.prepared(i);
  const double starts_apart_cm = rms_moved_cm(*scan.probe, prediction.start, other.start);
  if (!from_features && features != nullptr && starts_apart_cm < reach_cm) {
    // The other model's start lies within the match's reach of the first: the two matches would
    // fall into one basin, right or wrong (a lost track in a drive: both end metres short).
    std::snprintf(text, sizeof text,
                  "%s, and no independent start confirmed it: its FPFH features found none (%s), and standing still "
                  "is %.0f cm from the prediction, within the match's reach",
                  what, features->global.why_not.c_str(), starts_apart_cm);
    features_said_ = true;
    keep_first_match(match, text);
    return;
  }
  ScanMatch second = match_from(i, other, convergence);
  step1_iterations_ += second.iterations;
  const Pose kept = match.kept().world_from_data;
  const char* second_start = from_features                          ? "where its FPFH features put it"
                             : motion_.constant_velocity_at(state_, i) ? "the odometry's start"
                                                                       : "standing still";
  if (second.ok() && !second.health.doubtful()) {
    const Pose found = second.kept().world_from_data;
    const Pose apart = rigid_inverse(kept) * found;
    if (agree(kept, found)) {
      if (jumped) {  // two starts, one pose: confirmed (a jump says so in its note)
        std::snprintf(text, sizeof text, "%s; a match from %s ended %.1f cm / %.2f deg from it: confirmed", what,
                      second_start, translation_norm(apart), rotation_angle_deg(apart));
        add_note(match.health, text);
      }
      return;
    }
    const Pose correction = rigid_inverse(prediction.start) * found;
    if (jumped && translation_norm(correction) <= jump_cm) {
      // The second start's trusted match ends where the motion had the sensor go: kept, as any
      // match is that the motion model agrees with; the jump is said in its note.
      std::snprintf(text, sizeof text,
                    "%s; a trusted match from %s ended %.0f cm from the prediction, %.0f cm / %.1f deg from the first: "
                    "kept",
                    what, second_start, translation_norm(correction), translation_norm(apart), rotation_angle_deg(apart));
      measure_from_prediction(i, prediction, second);
      second.health.note = match.health.note;  // how the first came to be (the spring's release) stays said
      add_note(second.health, text);
      match = std::move(second);
      return;
    }
    std::snprintf(text, sizeof text, "%s, and a second match from %s ended %.0f cm / %.1f deg from it: not confirmed",
                  what, second_start, translation_norm(apart), rotation_angle_deg(apart));
  } else {
    std::snprintf(text, sizeof text, "%s, and a second match from another start was not trusted: not confirmed", what);
  }
  keep_first_match(match, text);
}

void SurveyMatcher::release_held_match(std::size_t i, const Prediction& prediction, ScanMatch& match,
                                       Convergence convergence) {
  const MotionSettings& motion = settings_.motion;
  if (!(prediction.objectives.start_spring_pairs > 0.0f) || !match.ok() || match.health.doubtful() || match.retry ||
      !(match.health.correction_cm > motion.sprung_release_cm)) {
    return;
  }
  Prediction released = prediction;
  released.objectives.start_spring_pairs = 0.0f;
  const LastMetascan held_metascan = last_metascan_;
  ScanMatch plain = match_from(i, released, convergence);
  step1_iterations_ += plain.iterations;
  const auto apart = [](const ScanMatch& a, const Pose& b) { return Pose(rigid_inverse(a.kept().world_from_data) * b); };
  const Pose held = match.kept().world_from_data;
  if (!plain.ok() || agree(plain.kept().world_from_data, held)) {
    last_metascan_ = held_metascan;
    return;
  }
  // Two answers: where the prediction held the sensor, and where the surfaces alone put it. The
  // scan's features are the independent start that decides.
  const double plain_cm = translation_norm(rigid_inverse(prediction.start) * plain.kept().world_from_data);
  std::string decided = "its FPFH features found no start";
  if (recovery_on(i)) {
    const RecoveredStart& features = features_start(i);
    if (features.global.found) {
      Prediction other;
      other.objectives.fine = motion_.fine_objective(state_, i);
      other.start = features.start;
      ScanMatch third = match_from(i, other, convergence);
      step1_iterations_ += third.iterations;
      if (third.ok() && !third.health.doubtful()) {
        const Pose found = third.kept().world_from_data;
        char text[400];
        if (!plain.health.doubtful() && !plain.retry && agree(plain.kept().world_from_data, found)) {
          std::snprintf(text, sizeof text,
                        "the spring to the prediction held it %.0f cm from it; without the spring the match ended %.0f "
                        "cm from it, and a match from where its FPFH features put it %.1f cm from that: kept without "
                        "the spring",
                        match.health.correction_cm, plain_cm, translation_norm(apart(plain, found)));
          measure_from_prediction(i, prediction, plain);
          plain.health.note = text;
          match = std::move(plain);
          return;
        }
        if (agree(held, found)) {
          last_metascan_ = held_metascan;
          return;
        }
        decided = "a match from where its FPFH features put it agreed with neither";
      } else {
        decided = "the match from where its FPFH features put it was not trusted";
      }
    } else {
      decided = "its FPFH features found no start (" + features.global.why_not + ")";
      features_said_ = true;
    }
  }
  last_metascan_ = held_metascan;
  char text[640];
  std::snprintf(text, sizeof text,
                "the spring to the prediction held it %.0f cm from it, where without the spring the match ended %.0f "
                "cm from it (%.0f cm / %.1f deg apart), and no independent start confirmed either: %s; whether the "
                "sensor changed speed or the surfaces slid is not known",
                match.health.correction_cm, plain_cm, translation_norm(apart(plain, held)),
                rotation_angle_deg(apart(plain, held)), decided.c_str());
  match.health.doubt = text;
  match.health.failed = HealthTest::kReach;  // a doubt about the move: the deskew's refinement keeps it
}

bool SurveyMatcher::agree(const Pose& a, const Pose& b) const {
  const Pose apart = rigid_inverse(a) * b;
  const MotionSettings& motion = settings_.motion;
  return translation_norm(apart) <= motion.confirm_agree_cm && rotation_angle_deg(apart) <= motion.confirm_agree_deg;
}

void SurveyMatcher::add_note(RegistrationHealth& health, const std::string& text) {
  health.note = health.note.empty() ? text : health.note + "; " + text;
}

void SurveyMatcher::measure_from_prediction(std::size_t i, const Prediction& prediction, ScanMatch& match) const {
  const Pose correction = rigid_inverse(prediction.start) * match.kept().world_from_data;
  match.health.correction_cm = translation_norm(correction);
  match.health.correction_deg = rotation_angle_deg(correction);
  match.health.moved_cm = rms_moved_cm(*state_.prepared(i).probe, prediction.start, match.kept().world_from_data);
}

void SurveyMatcher::keep_first_match(ScanMatch& match, const char* refuted) {
  if (!match.retry) {  // the first match itself went far: doubtful where it stands
    match.health.doubt = std::string("not confirmed (") + refuted + ")";
    match.health.failed = HealthTest::kReach;
    return;
  }
  match.retry.reset();
  match.health = std::move(match.first_health);
  match.health.doubt += std::string(" (") + refuted + "; the scan stays where its first match put it)";
  match.health.failed = HealthTest::kReach;  // about the move: the deskew's refinement keeps it
}

void SurveyMatcher::prefer_prediction_along_slide(std::size_t i, const Prediction& prediction, ScanMatch& match,
                                                  Convergence convergence) {
  const MotionSettings& motion = settings_.motion;
  const RegistrationHealth& health = match.health;
  if (!prediction.constant_velocity || !match.ok()) return;
  if (!(health.translation_constraint >= 0.0 && health.translation_constraint < motion.slide_constraint)) return;
  if (motion_.recent_error(state_, i).count < motion.confirm_min_history) return;
  const double bound_cm = settings_.pairwise_icp().max_pair_dist_cm;
  // The weakest direction is measured in the scan's own frame; the predicted start's is that frame
  // turned by the correction's few degrees.
  const Eigen::Vector3d& weakest = health.weakest_direction;
  const auto along_cm = [&](const Pose& pose) {
    double along = 0.0;
    without_move_along(prediction.start, pose, weakest, &along);
    return along;
  };
  const double slid_cm = along_cm(match.kept().world_from_data);
  if (!(std::abs(slid_cm) > bound_cm)) return;
  Prediction here;
  here.objectives.fine = motion_.fine_objective(state_, i);
  here.start = without_move_along(prediction.start, match.kept().world_from_data, weakest);
  here.start_bound_cm = static_cast<float>(bound_cm);
  const LastMetascan first_metascan = last_metascan_;  // a second match not kept changes nothing
  ScanMatch second = match_from(i, here, convergence);
  step1_iterations_ += second.iterations;
  // Not by the pair count: a forward-looking sensor sees past the map's end, and those points pair
  // only when the scan slides back along the corridor, so the slid match pairs more; its pairs sit
  // farther apart.
  const bool better = second.ok() && !second.health.doubtful() &&
                      std::abs(along_cm(second.kept().world_from_data)) < std::abs(slid_cm) &&
                      second.health.rms_cm < motion.slide_rms_factor * health.rms_cm;
  if (!better) {
    last_metascan_ = first_metascan;
    return;
  }
  const Pose found = second.kept().world_from_data;
  const double second_cm = along_cm(found);
  char text[400];
  std::snprintf(text, sizeof text,
                "its first match slid %.0f cm from the prediction along the direction its surfaces pin least (%.3f "
                "times the best, RMS %.1f cm); a match from the prediction along it ended %.0f cm along, RMS %.1f cm: "
                "kept",
                slid_cm, health.translation_constraint, health.rms_cm, second_cm, second.health.rms_cm);
  measure_from_prediction(i, prediction, second);
  second.health.note = health.note;
  add_note(second.health, text);
  match = std::move(second);
}

bool SurveyMatcher::recovery_on(std::size_t i) const {
  return settings_.recovery.enabled && i >= 1 && state_.registered(i - 1);
}

const RecoveredStart& SurveyMatcher::features_start(std::size_t i) {
  if (!features_start_ || features_start_->first != i) features_start_.emplace(i, recovery_.find(state_, i));
  return features_start_->second;
}

void SurveyMatcher::recover(std::size_t i, const Prediction& prediction, ScanMatch& match, Pose& start,
                            Convergence convergence) {
  if (!recovery_on(i)) return;
  if (match.ok() && !match.health.doubtful()) return;
  // An odometry start is the user's: its match keeps its pose, and only its verdict may change
  // (two independent starts, one pose). A constant-velocity start is ours: a trusted match from the
  // features replaces it.
  const bool may_replace = prediction.constant_velocity;
  if (!may_replace && !match.ok()) return;
  const RecoveredStart& found = features_start(i);
  char text[400];
  if (!found.global.found) {
    if (match.ok() && !features_said_) {
      match.health.doubt += " (registered again without a start, from its FPFH features: " + found.global.why_not + ")";
    }
    return;
  }
  Prediction from_features;
  from_features.objectives.fine = motion_.fine_objective(state_, i);
  from_features.start = found.start;
  ScanMatch again = match_from(i, from_features, convergence);
  step1_iterations_ += again.iterations;
  // A doubt that says the match may be stuck where its start left it (out of reach, not settled,
  // surfaces apart) is answered by a second start: two independent ones ending at one pose.
  const auto start_dependent = [](const RegistrationHealth& h) {
    return h.failed == HealthTest::kReach || h.failed == HealthTest::kBeyondBound || h.failed == HealthTest::kEdge;
  };
  const Pose apart = match.ok() && again.ok() ? Pose(rigid_inverse(match.kept().world_from_data) * again.kept().world_from_data) : Pose::Identity();
  const bool agreed = match.ok() && again.ok() && agree(match.kept().world_from_data, again.kept().world_from_data);
  if (agreed && start_dependent(match.health) && (!again.health.doubtful() || start_dependent(again.health))) {
    std::snprintf(text, sizeof text,
                  "trusted: the match from %s and one from its FPFH features (%zu of %zu feature pairs agreeing) "
                  "ended %.1f cm / %.2f deg apart; alone, it was doubtful: %s",
                  may_replace ? "the motion model's start" : "the odometry's start", found.global.inliers,
                  found.global.correspondences, translation_norm(apart), rotation_angle_deg(apart),
                  match.health.doubt.c_str());
    RegistrationHealth& confirmed = may_replace ? again.health : match.health;
    add_note(confirmed, text);
    confirmed.doubt.clear();
    confirmed.failed = HealthTest::kNone;
    confirmed.out_of_reach = false;
    if (!may_replace) return;
  }
  if (!may_replace || !again.ok() || again.health.doubtful()) {
    if (again.ok() && !again.health.doubtful()) {
      std::snprintf(text, sizeof text,
                    " (registered again without a start, %zu of %zu feature pairs agreeing: a trusted match from "
                    "there ended %.0f cm / %.1f deg from this one)",
                    found.global.inliers, found.global.correspondences, translation_norm(apart),
                    rotation_angle_deg(apart));
    } else {
      std::snprintf(text, sizeof text,
                    " (registered again without a start, %zu of %zu feature pairs agreeing, and matched from there: %s)",
                    found.global.inliers, found.global.correspondences,
                    again.ok() ? again.health.doubt.c_str() : to_string(again.first.stop));
    }
    if (match.ok()) match.health.doubt += text;
    return;
  }
  // Trusted. How far the prediction was off is measured from it (the adaptive bound learns from it).
  measure_from_prediction(i, prediction, again);
  again.health.recovered_inliers = found.global.inliers;
  match = std::move(again);
  start = found.start;
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
  last_metascan_ = {};
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
