#include "minemap/registration/health.hpp"

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <vector>

namespace minemap {

void HealthSettings::validate() const {
  if (!(wide_factor >= 1.0f) || !std::isfinite(wide_factor)) throw std::invalid_argument("health: wide_factor must be >= 1");
  for (const double f : {min_paired_fraction, max_beyond_bound_fraction, max_edge_fraction, min_translation_constraint}) {
    if (!(f >= 0.0 && f <= 1.0)) throw std::invalid_argument("health: fractions must lie in [0, 1]");
  }
  if (!(max_reach > 0.0) || std::isnan(max_reach)) throw std::invalid_argument("health: max_reach must be > 0");
  if (probe_stride < 1) throw std::invalid_argument("health: probe_stride must be >= 1");
}

RegistrationHealth judge_registration(ComputeBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                                      const Pose& start, std::span<const WorldModel> models, const IcpSettings& icp,
                                      const HealthSettings& settings, float reach_bound_cm,
                                      const SurfaceNormals* data_planes) {
  RegistrationHealth health;
  if (!settings.enabled || models.empty()) return health;
  health.judged = true;
  health.pair_bound_cm = icp.max_pair_dist_cm;
  const Pose correction = rigid_inverse(start) * world_from_data;
  health.correction_cm = translation_norm(correction);
  health.correction_deg = rotation_angle_deg(correction);
  std::vector<ModelPlacement> placed;
  placed.reserve(models.size());
  for (const WorldModel& model : models) {
    placed.push_back({model.cloud, rigid_inverse(model.world_from_model) * world_from_data, model.skip});
  }
  const float bound = icp.max_pair_dist_cm;
  const std::vector<NearestPair> nearest =
      backend.nearest(data, placed, SearchMethod::kExact, PairingSettings{settings.wide_factor * bound});
  const double bound2 = double(bound) * bound, half2 = bound2 / 4.0;
  std::size_t within_wide = 0, paired = 0, edge = 0;
  double sum2 = 0.0;
  for (const NearestPair& pair : nearest) {  // in data order: a deterministic sum
    if (pair.squared_distance_cm2 < 0.0f) continue;
    ++within_wide;
    const double d2 = pair.squared_distance_cm2;
    if (d2 > bound2) continue;
    ++paired;
    sum2 += d2;
    if (d2 > half2) ++edge;
  }
  health.data_points = nearest.size();
  const auto fraction = [](std::size_t part, std::size_t whole) { return whole ? double(part) / double(whole) : 0.0; };
  health.paired_fraction = fraction(paired, nearest.size());
  health.beyond_bound_fraction = fraction(within_wide - paired, within_wide);
  health.edge_fraction = fraction(edge, paired);
  health.rms_cm = paired ? std::sqrt(sum2 / double(paired)) : 0.0;
  // The path of each paired data point (the overlap: where the match was decided) from the start to
  // the end, in the data frame: |(C - I) p|, C the correction. Unpaired points far from the overlap
  // (a 250 m map segment) would swing far under a small turn and say nothing about reach.
  const Eigen::Matrix3d rotation_minus_identity = correction.block<3, 3>(0, 0) - Eigen::Matrix3d::Identity();
  const Eigen::Vector3d translation = correction.block<3, 1>(0, 3);
  const std::span<const Eigen::Vector3f> points = data.points();
  double moved2 = 0.0;
  std::vector<Eigen::Vector3f> paired_points;  // for the constraint test
  if (data_planes != nullptr) paired_points.reserve(paired);
  for (std::size_t k = 0; k < nearest.size() && k < points.size(); ++k) {
    if (nearest[k].squared_distance_cm2 < 0.0f || double(nearest[k].squared_distance_cm2) > bound2) continue;
    moved2 += (rotation_minus_identity * points[k].cast<double>() + translation).squaredNorm();
    if (data_planes != nullptr) paired_points.push_back(points[k]);
  }
  health.moved_cm = paired ? std::sqrt(moved2 / double(paired)) : 0.0;
  if (data_planes != nullptr) {
    const Matrix6d information = point_to_plane_information(paired_points, *data_planes);
    health.translation_constraint = translation_constraint_ratio(information, &health.weakest_direction);
    health.rotation_constraint = rotation_constraint_ratio(information, &health.weakest_axis);
  }
  char text[240];
  const float reach = reach_bound_cm > 0.0f ? reach_bound_cm : bound;
  if (health.moved_cm > settings.max_reach * reach) {
    std::snprintf(text, sizeof text,
                  "the match moved its points %.0f cm (RMS), %.1f times the %g cm pair bound (more than %.1f): it "
                  "started out of reach; check it, give a closer start, or widen --max-pair-dist-cm",
                  health.moved_cm, health.moved_cm / reach, double(reach), settings.max_reach);
    health.doubt = text;
    health.out_of_reach = true;
    health.failed = HealthTest::kReach;
  } else if (health.paired_fraction < settings.min_paired_fraction) {
    std::snprintf(text, sizeof text, "only %.0f%% of its points paired within %g cm (fewer than %.0f%%): little overlap",
                  100.0 * health.paired_fraction, double(bound), 100.0 * settings.min_paired_fraction);
    health.doubt = text;
    health.failed = HealthTest::kPaired;
  } else if (health.beyond_bound_fraction > settings.max_beyond_bound_fraction) {
    std::snprintf(text, sizeof text,
                  "%.0f%% of its counterparts lie beyond the %g cm pair bound (more than %.0f%%): the surfaces do not "
                  "meet; start closer or widen --max-pair-dist-cm",
                  100.0 * health.beyond_bound_fraction, double(bound), 100.0 * settings.max_beyond_bound_fraction);
    health.doubt = text;
    health.failed = HealthTest::kBeyondBound;
  } else if (health.edge_fraction > settings.max_edge_fraction) {
    std::snprintf(text, sizeof text,
                  "%.0f%% of its pairs lie in the outer half of the %g cm pair bound (more than %.0f%%): not settled "
                  "onto the surfaces",
                  100.0 * health.edge_fraction, double(bound), 100.0 * settings.max_edge_fraction);
    health.doubt = text;
    health.failed = HealthTest::kEdge;
  } else if (health.translation_constraint >= 0.0 &&
             health.translation_constraint < settings.min_translation_constraint) {
    const Eigen::Vector3d& d = health.weakest_direction;
    std::snprintf(text, sizeof text,
                  "degenerate: its surfaces pin the motion along (%.2f, %.2f, %.2f) in the scan's frame %.4f times as "
                  "well as the best direction (less than %g): it may have slid along it (a smooth tunnel)",
                  d.x(), d.y(), d.z(), health.translation_constraint, settings.min_translation_constraint);
    health.doubt = text;
    health.failed = HealthTest::kConstraint;
  }
  return health;
}

}  // namespace minemap
