#include "minemap/slam/survey_state.hpp"

#include <algorithm>
#include <array>
#include <utility>

namespace minemap::detail {

std::size_t SurveyState::add(const Scan& scan, PreparedScan prepared) {
  ScanState& state = scans_.emplace_back();
  state.odometry = scan.world_from_points();
  state.points_from_file = rigid_inverse(scan.world_from_points()) * scan.pose_cm;
  ScanOutcome& outcome = state.outcome;
  outcome.name = scan.name;
  outcome.initial_pose_cm = scan.pose_cm;
  outcome.pose_cm = scan.pose_cm;
  outcome.frames.push_back({scan.pose_cm, 0});
  outcome.world_from_points = state.odometry;
  const std::size_t i = scans_.size() - 1;
  if (i > 0 && first_moved_ > i && scan.pose_cm != scans_.front().outcome.initial_pose_cm) first_moved_ = i;
  set_prepared(i, std::move(prepared));
  return i;
}

void SurveyState::set_prepared(std::size_t i, PreparedScan prepared) {
  ScanOutcome& outcome = scans_[i].outcome;
  outcome.points_in = prepared.points_in;
  outcome.points_used = prepared.used_points_cm ? prepared.used_points_cm->size() : 0;
  outcome.outliers_replaced = prepared.outliers_replaced;
  outcome.used_points_cm = prepared.used_points_cm;
  outcome.used_intensity = prepared.used_intensity;
  outcome.stamp_s = prepared.stamp_s;
  outcome.sweep_motion_cm = prepared.sweep_motion;
  scans_[i].prepared = std::move(prepared);
}

void SurveyState::place(std::size_t i, const Pose& world_from_points, const IcpResult& match) {
  place(i, world_from_points);
  ScanOutcome& outcome = scans_[i].outcome;
  outcome.last_match = match;
  outcome.registered = true;
  outcome.failure.clear();
}

void SurveyState::place(std::size_t i, const Pose& world_from_points) {
  ScanOutcome& outcome = scans_[i].outcome;
  outcome.world_from_points = world_from_points;
  outcome.pose_cm = world_from_points * scans_[i].points_from_file;
  outcome.frames.push_back({outcome.pose_cm, 1});
}

void SurveyState::fail(std::size_t i, const Pose& start, const IcpResult& match) {
  ScanOutcome& outcome = scans_[i].outcome;
  outcome.world_from_points = start;
  outcome.pose_cm = start * scans_[i].points_from_file;
  outcome.registered = false;
  outcome.last_match = match;
  outcome.health = {};
  outcome.failure = std::string(to_string(match.stop)) + " (" + std::to_string(match.pairs) + " pairs)";
}

void SurveyState::restore(std::size_t i, const ScanOutcome& saved) {
  ScanOutcome& outcome = scans_[i].outcome;
  ScanOutcome restored = saved;
  restored.points_in = outcome.points_in;
  restored.points_used = outcome.points_used;
  restored.outliers_replaced = outcome.outliers_replaced;
  restored.used_points_cm = outcome.used_points_cm;
  restored.used_intensity = outcome.used_intensity;
  outcome = std::move(restored);
}

Bounds3d SurveyState::bounds_at(std::size_t i, const Pose& world_from_points) const {
  const PreparedCloud& cloud = *scans_[i].prepared.model_cloud;
  if (cloud.empty()) return {};
  const std::array<Eigen::Vector3f, 2> corners = {cloud.bounds_min(), cloud.bounds_max()};
  return world_bounds(corners, world_from_points);
}

std::vector<std::size_t> SurveyState::nearby(std::size_t i, const Pose& at, std::size_t limit,
                                             double margin_cm) const {
  const Bounds3d bounds = bounds_at(i, at);
  std::vector<std::pair<double, std::size_t>> found;
  for (std::size_t j = 0; j < limit; ++j) {
    if (j == i || !bounds.intersects(bounds_at(j, pose(j)), margin_cm)) continue;
    const double distance = (pose(j).block<3, 1>(0, 3) - at.block<3, 1>(0, 3)).norm();
    found.emplace_back(distance, j);
  }
  std::sort(found.begin(), found.end());
  std::vector<std::size_t> out;
  for (const auto& [distance, j] : found) out.push_back(j);
  return out;
}

std::vector<WorldModel> SurveyState::models_of(std::span<const std::size_t> indices) const {
  std::vector<WorldModel> models;
  for (const std::size_t j : indices) models.push_back({scans_[j].prepared.model_cloud.get(), pose(j)});
  return models;
}

std::vector<ScanOutcome> SurveyState::outcomes() const {
  std::vector<ScanOutcome> out;
  out.reserve(scans_.size());
  for (const ScanState& state : scans_) out.push_back(state.outcome);
  return out;
}

}  // namespace minemap::detail
