// A match that went far, checked from a second start before it is trusted (SurveyMatcher's,
// slam/survey_matcher.hpp): a jump from the motion model's prediction or a far retry, confirmed
// from where the scan's features put it (confirm_far_match); a match the spring held to its
// prediction, matched again without it (release_held_match); a slide along a direction the
// surfaces hardly pin, matched again from the prediction along it (prefer_prediction_along_slide);
// a failed or doubtful match, registered again from the features alone (recover). Each keeps,
// replaces or names the match; two matches agree by one test (agree), and each step adds its word
// to the match's note (add_note). Not in the paper: its scans started from odometry.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "minemap/slam/survey_matcher.hpp"

namespace minemap::detail {

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

}  // namespace minemap::detail
