// A moving sensor's sweeps, after their first match (SurveyMatcher's, slam/survey_matcher.hpp):
// deskewed again by the step the match found and matched again (refine_deskew), judged over the
// recent sweeps for turns their surfaces cannot pin (doubt_unpinned_turn), and the first sweep, the
// survey's frame, matched again once the sweeps after it are in, its own motion over the sweep
// fitted against them first (rematch_first_sweep, fit_first_sweep; registration/sweep_fit.hpp).
// Not in the paper: its scanner stood still while it scanned.
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "minemap/slam/survey_matcher.hpp"

namespace minemap::detail {

void SurveyMatcher::refine_deskew(std::size_t i, const Scan& raw, const SweepTiming& timing,
                                  Convergence convergence) {
  if (!state_.registered(i)) return;
  bool models_changed = false;
  if (i == 1 && first_sweep_) {
    const SweepTiming first_timing = preparation_.timing_of(*first_sweep_);
    const Pose first_motion = motion_.sweep_motion(state_, 0, state_.pose(0), 1);
    state_.set_prepared(0, preparation_.prepare(*first_sweep_, control_, first_timing, first_motion));
    if (settings_.motion.first_sweep_rematch_scans <= 1) first_sweep_.reset();
    models_changed = true;
  }
  const Pose refined = motion_.sweep_motion(state_, i, state_.pose(i), i - 1);
  const std::optional<Pose>& used = state_.prepared(i).sweep_motion;
  const Pose change = used ? rigid_inverse(*used) * refined : refined;
  const MotionSettings& motion = settings_.motion;
  const bool deskew_again = models_changed || translation_norm(change) >= motion.refine_min_change_cm ||
                            rotation_angle_deg(change) >= motion.refine_min_change_deg;
  // A provisional match that the deskew keeps is still matched again, to ICP's least step.
  if (!deskew_again && convergence == Convergence::kFinal) return;
  PreparedScan first = state_.prepared(i);
  const RegistrationHealth first_health = state_.health(i);
  if (deskew_again) state_.set_prepared(i, preparation_.prepare(raw, control_, timing, refined));
  Prediction here;
  here.objectives.fine = motion_.fine_objective(state_, i);
  here.objectives.start_spring_pairs = motion_.start_spring_pairs(state_, i);  // held where the first match put it
  // It starts converged: a spinning sensor's refinement searches exactly (MotionSettings::refine_search).
  const RefineSearch search = settings_.motion.refine_search;
  here.objectives.exact_from_start =
      search == RefineSearch::kExact ||
      (search == RefineSearch::kWideExact && !narrow_field(state_, i, settings_.motion.sweep_spring_max_field_deg));
  here.start = state_.pose(i);
  here.start_bound_cm = settings_.pairwise_icp().max_pair_dist_cm;
  ScanMatch again = match_from(i, here);
  step1_iterations_ += again.iterations;
  if (!again.ok() || (again.health.doubtful() && !first_health.doubtful())) {
    state_.set_prepared(i, std::move(first));  // the first deskew's match stands
    return;
  }
  // The prediction's error is the first match's (the motion model's adaptive bound learns from it).
  again.health.correction_cm = first_health.correction_cm;
  again.health.correction_deg = first_health.correction_deg;
  again.health.moved_cm = first_health.moved_cm;
  again.health.retry_bound_cm = first_health.retry_bound_cm;
  again.health.recovered_inliers = first_health.recovered_inliers;
  // The refinement starts where the first match ended, so it cannot see how the match got there:
  // a doubt about the move (it started out of reach, or a jump from the prediction that no second
  // start confirmed: confirm_far_match) stands whatever the refined fit, and a note saying how a
  // move was confirmed or recovered stays with the scan.
  if (first_health.doubtful() && first_health.failed == HealthTest::kReach) {
    again.health.doubt = first_health.doubt;
    again.health.failed = first_health.failed;
    again.health.out_of_reach = first_health.out_of_reach;
  }
  if (again.health.note.empty()) again.health.note = first_health.note;
  place(i, again, here.start);
}

void SurveyMatcher::doubt_unpinned_turn(std::size_t i) {
  const std::optional<UnpinnedTurn> turn = motion_.unpinned_turn(state_, i);
  const MotionSettings& motion = settings_.motion;
  if (!turn || !(turn->deg > motion.max_unpinned_turn_deg) || state_.health(i).doubtful()) return;
  char text[640];
  std::snprintf(text, sizeof text,
                "its match and those of the %d sweeps before it turned the sensor by %.0f deg in all in %.1f s about "
                "axes their surfaces hardly pin (this one's (%.2f, %.2f, %.2f) in the scan's frame, %.3f times as "
                "well as the best axis; each less than %g): more than %g deg that the surfaces did not measure (a "
                "scanner whose pattern turns from sweep to sweep, a rosette's, turns its matches with it). Their "
                "turns about those axes are taken out: the map there assumes the sensor did not turn about them",
                turn->sweeps - 1, turn->deg, turn->seconds, turn->axis.x(), turn->axis.y(), turn->axis.z(),
                turn->constraint, motion.unpinned_turn_constraint, motion.max_unpinned_turn_deg);
  char earlier[300];
  std::snprintf(earlier, sizeof earlier,
                "one of the sweeps up to %s whose matches turned the sensor by %.0f deg in all in %.1f s about axes "
                "their surfaces hardly pin (%s says more); its turn about its own is taken out",
                state_.outcome(i).name.c_str(), turn->deg, turn->seconds, state_.outcome(i).name.c_str());
  // What the surfaces did not measure is not kept: each step of the run loses its turn about the
  // axis its match pinned least (the rest of the match stays), the sweeps chained again from the
  // first one's start; the next prediction repeats no such turn, and the sweeps after them see the
  // walls from a map of several patterns, not of one. Each sweep of the run is named.
  const std::size_t first = i + 1 - static_cast<std::size_t>(turn->sweeps);
  std::vector<Pose> steps;
  for (std::size_t k = first; k <= i; ++k) steps.push_back(rigid_inverse(state_.pose(k - 1)) * state_.pose(k));
  for (std::size_t k = first; k <= i; ++k) {
    const Pose& step = steps[k - first];
    const Eigen::Vector3d& axis = state_.health(k).weakest_axis;
    const Eigen::Quaterniond rotation(Eigen::Matrix3d(step.block<3, 3>(0, 0)));
    const double along = rotation.vec().dot(axis);
    Eigen::Quaterniond about(rotation.w(), along * axis.x(), along * axis.y(), along * axis.z());
    Pose kept = step;
    if (about.norm() > 0.0) kept.block<3, 3>(0, 0) = (rotation * about.normalized().conjugate()).toRotationMatrix();
    state_.place(k, state_.pose(k - 1) * kept);
    RegistrationHealth health = state_.health(k);
    if (health.doubtful()) continue;
    health.doubt = k == i ? text : earlier;
    health.failed = HealthTest::kUnpinnedTurn;
    state_.judged(k, std::move(health));
  }
}

void SurveyMatcher::rematch_first_sweep(std::size_t i) {
  const int after = settings_.motion.first_sweep_rematch_scans;
  if (after <= 1 || i != static_cast<std::size_t>(after) || !first_sweep_) return;
  const Scan first = std::move(*first_sweep_);
  first_sweep_.reset();
  std::vector<std::size_t> later;
  for (std::size_t j = 1; j <= i; ++j) {
    if (!state_.registered(j)) return;
    later.push_back(j);
  }
  const SweepTiming timing = preparation_.timing_of(first);
  // One tree over the later sweeps' model points, in scan 0's frame; they move together, so the
  // tree moves with them (`shift`, applied to its frame) and is built once.
  const Pose frame = state_.pose(0);
  const std::shared_ptr<const PreparedCloud> union_cloud = local_map_.whole_union(state_, later, frame);
  const Pose step_motion = motion_.sweep_motion(state_, 0, state_.pose(0), 1);
  const std::optional<SweepFit> fit = fit_first_sweep(first, timing, *union_cloud, frame, step_motion);
  Pose shift = Pose::Identity();
  // Rounds of the paper's ICP against them, deskewed by the fitted motion (one round: it is the
  // same in every round) or by the step into sweep 1 as the last round left it.
  RegistrationHealth last_health;  // the first sweep's last match against them
  const auto match_rounds = [&](const SweepFit* fitted) {
    int rounds = 0;
    for (int round = 0; round < kFirstSweepRounds; ++round) {
      const Pose motion = fitted ? fitted->motion : motion_.sweep_motion(state_, 0, state_.pose(0), 1);
      const Pose start = fitted ? fitted->world_from_sweep * rigid_inverse(state_.points_from_file(0)) : state_.pose(0);
      PreparedScan prepared = preparation_.prepare(first, control_, timing, motion);
      const std::vector<WorldModel> models{{union_cloud.get(), shift * frame}};
      const ScanMatch match = registration_.register_scan(prepared, start, [&](float, const Pose&) { return models; });
      step1_iterations_ += match.iterations;
      if (match.ok()) last_health = match.health;
      if (!match.ok() || match.health.doubtful()) break;
      // Scan 0 was matched to where the later sweeps say it stands; they move so that it stays.
      const Pose move = state_.pose(0) * rigid_inverse(match.kept().world_from_data);
      for (const std::size_t j : later) state_.place(j, move * state_.pose(j));
      state_.set_prepared(0, std::move(prepared));
      shift = move * shift;
      ++rounds;
      if (fitted || (translation_norm(move) < settings_.motion.refine_min_change_cm &&
                     rotation_angle_deg(move) < settings_.motion.refine_min_change_deg)) {
        break;
      }
    }
    return rounds;
  };
  const bool fitted = fit && fit->converged;
  int rounds = fitted ? match_rounds(&*fit) : 0;
  const bool fit_kept = rounds > 0;
  if (!fit_kept) rounds = match_rounds(nullptr);  // no fit, or its match doubtful: the step's motion
  char text[320];
  if (rounds > 0) {
    std::snprintf(text, sizeof text,
                  "the first sweep (%s) was matched again against the %zu sweeps after it once they were in (%d "
                  "round(s)); they moved together %.1f cm and turned %.2f deg about it",
                  first.name.c_str(), i, rounds, translation_norm(shift), rotation_angle_deg(shift));
  } else {
    std::snprintf(text, sizeof text,
                  "the first sweep (%s) was matched again against the %zu sweeps after it once they were in, and no "
                  "match was trusted: they stay where they were",
                  first.name.c_str(), i);
  }
  std::string note = text;
  if (fit_kept) {
    std::snprintf(text, sizeof text,
                  "; its own motion over the sweep, fitted against them%s, turned %.1f deg and moved %.1f cm (the "
                  "step into sweep 1 said %.1f deg, %.1f cm)",
                  fit->settled ? " (settled within the pairs' churn at its last stage's cap)" : "",
                  rotation_angle_deg(fit->motion), translation_norm(fit->motion), rotation_angle_deg(step_motion),
                  translation_norm(step_motion));
    note += text;
  } else if (fit) {
    std::snprintf(text, sizeof text,
                  "; its own motion over the sweep %s (%zu pairs with a plane, %d iterations), so it was deskewed "
                  "by the step into sweep 1",
                  fitted ? "was fitted, but the match from there was not trusted" : "could not be fitted against them",
                  fit->pairs, fit->iterations);
    note += text;
  }
  notes_.push_back(std::move(note));
  doubt_unfitted_first_sweep(fit, fit_kept, step_motion, i, std::move(last_health));
}

void SurveyMatcher::doubt_unfitted_first_sweep(const std::optional<SweepFit>& fit, bool fit_kept,
                                               const Pose& step_motion, std::size_t later,
                                               RegistrationHealth health) {
  const double turned_deg = rotation_angle_deg(step_motion);
  if (!fit || fit_kept || !(turned_deg > settings_.motion.unfitted_first_sweep_max_turn_deg)) return;
  char text[480];
  std::snprintf(text, sizeof text,
                "its own motion over the sweep %s against the %zu sweeps after it, and the step into sweep 1 turned "
                "the sensor %.1f deg over one sweep (more than %g): deskewed by that step, its shape, and with it "
                "the frame of the whole map, may be off by part of that turn; check it, or start the survey with "
                "the sensor still",
                fit->converged ? "was fitted, but the match from there was not trusted," : "could not be fitted",
                later, turned_deg, settings_.motion.unfitted_first_sweep_max_turn_deg);
  health.judged = true;  // its last match's figures, where one was made
  health.doubt = health.doubt.empty() ? std::string(text) : health.doubt + "; " + text;
  state_.judged(0, std::move(health));
}

std::optional<SweepFit> SurveyMatcher::fit_first_sweep(const Scan& first, const SweepTiming& timing,
                                                       const PreparedCloud& later, const Pose& frame,
                                                       const Pose& step_motion) {
  if (!settings_.motion.first_sweep_fit || timing.empty()) return std::nullopt;
  // The fit takes the sweep in its file's frame, where the deskew's motion is.
  const Pose file_from_points = rigid_inverse(state_.points_from_file(0));
  std::vector<Eigen::Vector3d> points(first.size());
  for (std::size_t k = 0; k < points.size(); ++k) {
    points[k] = (file_from_points * first.points_cm[k].cast<double>().homogeneous()).head<3>();
  }
  const SurfaceNormals normals(later.points(), settings_.plane_cell_cm);
  SweepFitSettings fit_settings = settings_.motion.first_sweep_fit_settings;
  fit_settings.max_pair_dist_cm = settings_.pairwise_icp().max_pair_dist_cm;
  return fit_sweep(backend_, points, timing.fraction, WorldModel{&later, frame}, normals,
                   state_.pose(0) * state_.points_from_file(0), step_motion, fit_settings);
}

}  // namespace minemap::detail
