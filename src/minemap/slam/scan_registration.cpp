#include "minemap/slam/scan_registration.hpp"

#include <algorithm>
#include <cstdio>

namespace minemap::detail {

RegistrationHealth ScanRegistration::judge(const PreparedScan& scan, const Pose& pose, const Pose& start,
                                           std::span<const WorldModel> models, float reach_bound_cm) const {
  return judge_registration(backend_, *scan.probe, pose, start, models, icp_, settings_.health, reach_bound_cm,
                            scan.planes_or_null());
}

const PreparedCloud& ScanRegistration::data_of(const PreparedScan& scan, Convergence convergence) const {
  return convergence == Convergence::kProvisional && settings_.motion.provisional_probe ? *scan.probe : *scan.cloud;
}

IcpSettings ScanRegistration::icp_for(const PreparedScan& scan, Convergence convergence) const {
  IcpSettings icp = icp_;
  icp.termination.min_pairs = settings_.min_pairs_for(data_of(scan, convergence).points().size());
  if (convergence == Convergence::kProvisional) {
    icp.termination.min_translation_step_cm *= settings_.motion.provisional_step_factor;
    icp.termination.min_rotation_step_deg *= settings_.motion.provisional_step_factor;
  }
  return icp;
}

IcpResult ScanRegistration::run_icp(const PreparedScan& scan, const PreparedCloud& data, const Pose& start,
                                    std::span<const WorldModel> models, IcpSettings icp, IcpObjective objective) const {
  std::vector<Eigen::Vector3f> normals;
  if (objective == IcpObjective::kPointToPlane && scan.planes) {
    icp.objective = objective;
    normals.reserve(data.points().size());
    for (const Eigen::Vector3f& p : data.points()) {
      const Eigen::Vector3f* normal = scan.planes->at(p);
      normals.push_back(normal != nullptr ? *normal : Eigen::Vector3f::Zero());
    }
  }
  return register_icp(backend_, data, start, models, icp, normals);
}

WideMatch ScanRegistration::match_from_wide_bound(const PreparedScan& scan, const Pose& start,
                                                  std::span<const WorldModel> models, float bound_cm,
                                                  Convergence convergence, bool coarse_on_probe,
                                                  const MatchObjectives& objectives) const {
  const IcpSettings icp = icp_for(scan, convergence);
  IcpSettings wide = icp;
  wide.max_pair_dist_cm = bound_cm;
  wide.refine_pair_dist_fraction = 0.0f;
  wide.robust_scale_fraction = objectives.coarse_kernel_fraction;
  wide.start_spring_pairs = objectives.start_spring_pairs;
  WideMatch match;
  const PreparedCloud& coarse_data = coarse_on_probe ? *scan.probe : data_of(scan, convergence);
  if (coarse_on_probe) wide.termination.min_pairs = settings_.min_pairs_for(coarse_data.points().size());
  const IcpResult coarse = register_icp(backend_, coarse_data, start, models, wide);
  match.iterations += coarse.iterations();
  if (!coarse.ok()) {
    match.failure = to_string(coarse.stop);
    match.failed = coarse;
    return match;
  }
  IcpSettings fine_icp = icp;
  fine_icp.start_spring_pairs = objectives.start_spring_pairs;
  IcpResult fine = run_icp(scan, data_of(scan, convergence), coarse.world_from_data, models, fine_icp, objectives.fine);
  match.iterations += fine.iterations();
  if (!fine.ok()) {
    match.failure = to_string(fine.stop);
    match.failed = fine;
    match.failed.world_from_data = start;
    return match;
  }
  match.health = judge(scan, fine.world_from_data, start, models, bound_cm);
  match.fine = std::move(fine);
  return match;
}

ScanMatch ScanRegistration::register_scan(const PreparedScan& scan, const Pose& start,
                                          const ModelsForBound& models_for, float start_bound_cm,
                                          Convergence convergence, const MatchObjectives& objectives) const {
  ScanMatch match;
  float widest_cm = icp_.max_pair_dist_cm;
  if (start_bound_cm > widest_cm) {
    // The motion model's adaptive bound: the first match is a wide one, coarse to fine.
    const std::vector<WorldModel> models = models_for(start_bound_cm, start);
    WideMatch wide =
        match_from_wide_bound(scan, start, models, start_bound_cm, convergence, settings_.motion.wide_coarse_probe,
                              objectives);
    match.iterations = wide.iterations;
    if (!wide.fine) {
      match.first = wide.failed;
      return match;
    }
    match.first = std::move(*wide.fine);
    match.health = std::move(wide.health);
    widest_cm = start_bound_cm;
  } else {
    const std::vector<WorldModel> models = models_for(icp_.max_pair_dist_cm, start);
    IcpSettings first_icp = icp_for(scan, convergence);
    first_icp.start_spring_pairs = objectives.start_spring_pairs;
    if (objectives.exact_from_start && first_icp.method == SearchMethod::kApproximate) {
      first_icp.method = SearchMethod::kExact;
    }
    match.first = run_icp(scan, data_of(scan, convergence), start, models, first_icp, objectives.fine);
    match.iterations = match.first.iterations();
    if (!match.first.ok()) return match;
    match.health = judge(scan, match.first.world_from_data, start, models);
  }
  std::string tried;
  for (const float factor : settings_.retry_bound_factors) {
    if (!match.health.doubtful()) return match;
    // Each rung is clamped to the widest retry, so a wide bound of the user's own (2 m, where the
    // 4x rung would be 8 m) still gets the 4 m retry the default's 25 cm reaches: a match that
    // started out of 2 m's reach and converges right is then trusted, as it is at the default.
    const float bound = std::min(factor * icp_.max_pair_dist_cm, settings_.max_retry_bound_cm);
    if (bound <= widest_cm) continue;
    widest_cm = bound;
    const std::vector<WorldModel> wide_models = models_for(bound, match.first.world_from_data);
    WideMatch retry =
        match_from_wide_bound(scan, start, wide_models, bound, convergence, false, {0.0f, objectives.fine});
    match.iterations += retry.iterations;
    if (!retry.fine) continue;
    if (retry.health.doubtful()) {
      char text[32];
      std::snprintf(text, sizeof text, "%g cm", double(bound));
      tried += (tried.empty() ? "" : ", ") + std::string(text);
      continue;
    }
    retry.health.retry_bound_cm = bound;
    match.first_health = std::move(match.health);
    match.retry = std::move(retry.fine);
    match.health = std::move(retry.health);
    return match;
  }
  if (!tried.empty()) match.health.doubt += " (tried again from " + tried + ": still doubtful)";
  return match;
}

}  // namespace minemap::detail
