#include "minemap/slam/motion_model.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <span>

#include <Eigen/Geometry>

namespace minemap::detail {

bool MotionPrediction::constant_velocity_at(const SurveyState& state, std::size_t i) const {
  switch (settings_.motion.model) {
    case MotionModel::kOdometry: return false;
    case MotionModel::kConstantVelocity: return true;
    case MotionModel::kAuto: return !state.odometry_moved_by(i);
  }
  return false;
}

bool MotionPrediction::moving(const SurveyState& state, std::size_t i) const {
  return state.prepared(i).sweep_s > 0.0 || constant_velocity_at(state, i);
}

IcpObjective MotionPrediction::fine_objective(const SurveyState& state, std::size_t i) const {
  return settings_.motion.plane_objective && moving(state, i) ? IcpObjective::kPointToPlane
                                                                : IcpObjective::kPointToPoint;
}

double MotionPrediction::local_map_cell_cm(const SurveyState& state, std::size_t i) const {
  return moving(state, i) ? settings_.motion.local_map_cell_cm : 0.0;
}

Pose MotionPrediction::file_pose(const SurveyState& state, std::size_t i, const Pose& world_from_points) {
  return world_from_points * state.points_from_file(i);
}

double MotionPrediction::time_ratio(const SurveyState& state, std::size_t a, std::size_t b, std::size_t c,
                                    std::size_t d, double fallback) {
  const double top = state.prepared(b).stamp_s - state.prepared(a).stamp_s;
  const double bottom = state.prepared(d).stamp_s - state.prepared(c).stamp_s;
  if (!(top > 0.0) || !(bottom > 0.0) || !std::isfinite(top) || !std::isfinite(bottom)) return fallback;
  return top / bottom;
}

namespace {

/// The azimuth the points span about the sensor: the z axis of their file's frame, `file_from_points`
/// taking them there (degrees, in 5 degree bins; a bin counts when it holds at least 1 in 500 of the
/// points, so stray returns do not widen it). Points stored about another origin (far from their
/// frame's, read relative to a local one) are measured where the sensor stood, not about that origin.
double azimuth_span_deg(std::span<const Eigen::Vector3f> points, const Pose& file_from_points) {
  constexpr int kBins = 72;
  std::array<std::size_t, kBins> count{};
  const bool moved = !file_from_points.isIdentity(0.0);
  for (const Eigen::Vector3f& stored : points) {
    const Eigen::Vector3d p = moved ? Eigen::Vector3d((file_from_points * stored.cast<double>().homogeneous()).head<3>())
                                    : Eigen::Vector3d(stored.cast<double>());
    const double angle = std::atan2(p.y(), p.x());  // (-pi, pi]
    const int bin = std::clamp(static_cast<int>((angle + std::numbers::pi) / (2.0 * std::numbers::pi) * kBins), 0,
                               kBins - 1);
    ++count[static_cast<std::size_t>(bin)];
  }
  int taken = 0;
  for (const std::size_t c : count) taken += 500 * c >= points.size() && c > 0 ? 1 : 0;
  return taken * (360.0 / kBins);
}

}  // namespace

bool narrow_field(const SurveyState& state, std::size_t i, double max_field_deg) {
  if (!(max_field_deg < 360.0)) return true;
  const PreparedScan& scan = state.prepared(i);
  return scan.cloud && azimuth_span_deg(scan.cloud->points(), rigid_inverse(state.points_from_file(i))) < max_field_deg;
}

float MotionPrediction::start_spring_pairs(const SurveyState& state, std::size_t i) const {
  const MotionSettings& motion = settings_.motion;
  if (!(state.prepared(i).sweep_s > 0.0) || !(motion.sweep_start_spring_pairs > 0.0)) return 0.0f;
  const PredictionError recent = recent_error(state, i);
  if (recent.count < motion.confirm_min_history) return 0.0f;
  // (A sweep not yet prepared, the deskew's first prediction, is not judged by its field.)
  if (state.prepared(i).cloud && !narrow_field(state, i, motion.sweep_spring_max_field_deg)) return 0.0f;
  const double ratio = motion.sweep_spring_full_error_cm / std::max(recent.translation_rms_cm, 1e-9);
  return static_cast<float>(motion.sweep_start_spring_pairs * std::min(1.0, ratio * ratio));
}

Prediction MotionPrediction::predict(const SurveyState& state, std::size_t i) const {
  Prediction prediction;
  prediction.start_bound_cm = settings_.pairwise_icp().max_pair_dist_cm;
  prediction.objectives.fine = fine_objective(state, i);
  prediction.objectives.start_spring_pairs = start_spring_pairs(state, i);
  if (!constant_velocity_at(state, i)) {
    const Pose odometry_step = rigid_inverse(state.odometry(i - 1)) * state.odometry(i);
    prediction.start = state.pose(i - 1) * odometry_step;
    return prediction;
  }
  prediction.constant_velocity = true;
  const Pose previous = file_pose(state, i - 1, state.pose(i - 1));
  Pose step = Pose::Identity();
  if (i >= 2 && state.registered(i - 1) && state.registered(i - 2)) {
    // The plain step keeps its own expression, so every prediction the rule leaves alone keeps
    // its bits; the adjusted one is found between the scans' points frames and turned into the
    // files' frames here.
    if (const std::optional<Pose> measured = step_along_weak_direction(state, i)) {
      step = rigid_inverse(state.points_from_file(i - 2)) * *measured * state.points_from_file(i - 1);
    } else {
      step = rigid_inverse(file_pose(state, i - 2, state.pose(i - 2))) * previous;
    }
    step = motion_fraction(step, time_ratio(state, i - 1, i, i - 2, i - 1, 1.0));
  }
  prediction.start = previous * step * rigid_inverse(state.points_from_file(i));
  prediction.start_bound_cm = std::max(prediction.start_bound_cm, adaptive_bound_cm(state, i));
  // Keyframes without times only: a timed sweep's first match is provisional, its deskew matches
  // it again, and there the kernel lost the simulated spinning loop's closure (docs/benchmarks.md).
  if (settings_.motion.wide_coarse_kernel_fraction > 0.0 && !(state.prepared(i).sweep_s > 0.0) &&
      recent_error(state, i).count > 0) {
    prediction.objectives.coarse_kernel_fraction = static_cast<float>(settings_.motion.wide_coarse_kernel_fraction);
  }
  return prediction;
}

std::optional<Pose> MotionPrediction::step_along_weak_direction(const SurveyState& state, std::size_t i) const {
  const MotionSettings& motion = settings_.motion;
  const RegistrationHealth& last = state.health(i - 1);
  const double least = motion.weak_step_constraint;
  if (!(least > 0.0) || !(state.prepared(i).sweep_s > 0.0) || !last.judged || last.doubtful() ||
      !(last.translation_constraint >= 0.0 && last.translation_constraint < least) ||
      !(last.weakest_direction.squaredNorm() > 0.5)) {
    return std::nullopt;
  }
  // The steps into the last weak_step_window scans that were pinned well along every direction,
  // each scaled to the last step's time (the sweeps' stamps), along the weak direction of scan i-1
  // (its data frame; a step's own frame turns little in a few sweeps).
  const Eigen::Vector3d& weak = last.weakest_direction;
  const std::size_t window = static_cast<std::size_t>(motion.weak_step_window);
  double sum_cm = 0.0;
  int count = 0;
  for (std::size_t k = i - 1; k >= 1 && k + window >= i; --k) {
    const RegistrationHealth& health = state.health(k);
    if (!state.registered(k) || !state.registered(k - 1) || !health.judged || health.doubtful() ||
        !(health.translation_constraint >= least)) {
      continue;
    }
    const Pose step = rigid_inverse(state.pose(k - 1)) * state.pose(k);
    sum_cm += step.block<3, 1>(0, 3).dot(weak) * time_ratio(state, i - 2, i - 1, k - 1, k, 1.0);
    ++count;
  }
  if (count < 3) return std::nullopt;
  Pose step = rigid_inverse(state.pose(i - 2)) * state.pose(i - 1);
  const double along_cm = step.block<3, 1>(0, 3).dot(weak);
  step.block<3, 1>(0, 3) += (sum_cm / count - along_cm) * weak;
  return step;
}

namespace {

/// The health measured a turn constraint below `least`, with its axis.
bool turn_unpinned(const RegistrationHealth& health, double least) {
  return health.judged && health.rotation_constraint >= 0.0 && health.rotation_constraint < least &&
         health.weakest_axis.squaredNorm() > 0.5;
}

}  // namespace

std::optional<UnpinnedTurn> MotionPrediction::unpinned_turn(const SurveyState& state, std::size_t i) const {
  const MotionSettings& motion = settings_.motion;
  const double least = motion.unpinned_turn_constraint;
  if (!(motion.max_unpinned_turn_deg > 0.0) || i < 1 || !(state.prepared(i).sweep_s > 0.0) ||
      !std::isfinite(state.prepared(i).stamp_s) || !state.registered(i) ||
      !turn_unpinned(state.health(i), least)) {
    return std::nullopt;
  }
  UnpinnedTurn turn;
  turn.constraint = state.health(i).rotation_constraint;
  turn.axis = state.health(i).weakest_axis;
  const double stamp_s = state.prepared(i).stamp_s;
  for (std::size_t k = i; k >= 1; --k) {
    const double start_s = state.prepared(k - 1).stamp_s;
    if (!state.registered(k) || !state.registered(k - 1) || !turn_unpinned(state.health(k), least) ||
        !(stamp_s - start_s <= motion.unpinned_turn_window_s + 1e-9)) {
      break;
    }
    const Eigen::AngleAxisd rotation(Eigen::Matrix3d(
        (rigid_inverse(state.pose(k - 1)) * state.pose(k)).block<3, 3>(0, 0)));
    const double about_rad = rotation.angle() * rotation.axis().dot(state.health(k).weakest_axis);
    turn.deg += std::abs(about_rad) * (180.0 / std::numbers::pi);
    ++turn.sweeps;
    turn.seconds = stamp_s - start_s;
  }
  return turn;
}

PredictionError MotionPrediction::recent_error(const SurveyState& state, std::size_t i) const {
  double sum_squares = 0.0, translation_squares = 0.0;
  PredictionError error;
  const std::size_t window = static_cast<std::size_t>(settings_.motion.adaptive_bound_window);
  for (std::size_t j = i > window ? i - window : 1; j < i; ++j) {
    if (!state.registered(j)) continue;
    // Scan 1 by constant velocity was predicted standing still: its correction is the step itself.
    if (j < 2 && constant_velocity_at(state, j)) continue;
    const RegistrationHealth& health = state.health(j);
    if (!health.judged || health.doubtful()) continue;
    sum_squares += health.moved_cm * health.moved_cm;
    translation_squares += health.correction_cm * health.correction_cm;
    ++error.count;
  }
  if (error.count > 0) {
    error.rms_cm = std::sqrt(sum_squares / error.count);
    error.translation_rms_cm = std::sqrt(translation_squares / error.count);
  }
  return error;
}

float MotionPrediction::adaptive_bound_cm(const SurveyState& state, std::size_t i) const {
  const MotionSettings& motion = settings_.motion;
  if (!(motion.adaptive_bound_sigmas > 0.0)) return 0.0f;
  const PredictionError error = recent_error(state, i);
  if (error.count == 0) return static_cast<float>(std::min<double>(motion.initial_bound_cm, settings_.max_retry_bound_cm));
  const double bound = motion.adaptive_bound_sigmas * error.rms_cm;
  return static_cast<float>(std::min<double>(bound, settings_.max_retry_bound_cm));
}

Pose MotionPrediction::alternative_start(const SurveyState& state, std::size_t i) const {
  if (constant_velocity_at(state, i)) {
    const Pose odometry_step = rigid_inverse(state.odometry(i - 1)) * state.odometry(i);
    return state.pose(i - 1) * odometry_step;
  }
  return file_pose(state, i - 1, state.pose(i - 1)) * rigid_inverse(state.points_from_file(i));
}

Pose MotionPrediction::sweep_motion(const SurveyState& state, std::size_t j, const Pose& pose_j,
                                    std::size_t other) const {
  const Pose here = file_pose(state, j, pose_j);
  const Pose there = file_pose(state, other, state.pose(other));
  // The step forward in time, from the earlier scan to the later, in the earlier one's frame.
  const bool later = other > j;
  const Pose step = later ? rigid_inverse(here) * there : rigid_inverse(there) * here;
  const std::size_t first = later ? j : other, second = later ? other : j;
  const double sweep = state.prepared(j).sweep_s;
  const double between = state.prepared(second).stamp_s - state.prepared(first).stamp_s;
  const double fraction = (between > 0.0 && std::isfinite(between)) ? std::min(sweep / between, 1.5) : 1.0;
  return motion_fraction(step, fraction);
}

Pose without_move_along(const Pose& predicted, const Pose& matched, const Eigen::Vector3d& direction,
                        double* along_cm) {
  Pose correction = rigid_inverse(predicted) * matched;
  const double along = direction.dot(correction.block<3, 1>(0, 3));
  correction.block<3, 1>(0, 3) -= along * direction;
  if (along_cm != nullptr) *along_cm = along;
  return predicted * correction;
}

}  // namespace minemap::detail
