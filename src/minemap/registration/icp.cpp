#include "minemap/registration/icp.hpp"

#include <vector>

#include "minemap/registration/horn.hpp"

namespace minemap {

const char* to_string(IcpStop stop) {
  switch (stop) {
    case IcpStop::kConverged: return "converged";
    case IcpStop::kMaxIterations: return "iteration cap reached";
    case IcpStop::kTooFewPairs: return "too few pairs (no overlap)";
    case IcpStop::kNumericFailure: return "numeric failure (NaN or degenerate geometry)";
  }
  return "?";
}

namespace {
std::vector<ModelPlacement> place(std::span<const WorldModel> models, const Pose& world_from_data) {
  std::vector<ModelPlacement> placed;
  placed.reserve(models.size());
  for (const auto& m : models) placed.push_back({m.cloud, rigid_inverse(m.world_from_model) * world_from_data});
  return placed;
}
}  // namespace

IcpResult register_icp(PairingBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                       std::span<const WorldModel> models, const IcpSettings& settings) {
  IcpResult result;
  result.world_from_data = world_from_data;
  Pose current = world_from_data;
  PairingSettings pairing{settings.max_pair_dist_cm};
  SearchMethod method = settings.method;
  const bool scheduled = settings.method == SearchMethod::kApproximate;
  const bool refine = settings.refine_max_pair_dist_cm > 0.0f && settings.refine_max_pair_dist_cm < settings.max_pair_dist_cm;
  bool refining = false;
  double previous_rms = std::numeric_limits<double>::infinity();

  for (int iteration = 0; iteration < settings.max_iterations; ++iteration) {
    const auto placed = place(models, current);
    const PairSums sums = backend.pair_and_sum(data, placed, method, pairing);
    if (sums.count < std::max(3, settings.min_pairs)) {
      result.stop = IcpStop::kTooFewPairs;
      result.pairs = static_cast<std::size_t>(sums.count);
      result.world_from_data = world_from_data;
      return result;
    }
    const double rms = sums.rms_cm();
    // The paper: approximate search only while the error keeps falling, then exact search.
    if (method == SearchMethod::kApproximate && iteration > 0 && !(rms < previous_rms)) {
      method = SearchMethod::kExact;
      previous_rms = std::numeric_limits<double>::infinity();
      --iteration;  // this pass does not count: redo it with exact pairs
      continue;
    }
    previous_rms = rms;
    const auto step = horn_transform(sums);
    if (!step || !is_valid_rigid(*step, 1e-6)) {
      result.stop = IcpStop::kNumericFailure;
      result.world_from_data = world_from_data;
      return result;
    }
    current = current * *step;
    (method == SearchMethod::kApproximate ? result.approximate_iterations : result.exact_iterations) += 1;
    if (refining) ++result.refine_iterations;
    result.pairs = static_cast<std::size_t>(sums.count);
    result.rms_cm = rms;
    if (!current.allFinite()) {
      result.stop = IcpStop::kNumericFailure;
      result.world_from_data = world_from_data;
      return result;
    }
    const bool small_step = translation_norm(*step) < settings.min_translation_step_cm &&
                            rotation_angle_deg(*step) < settings.min_rotation_step_deg;
    if (!small_step) continue;
    if (method == SearchMethod::kApproximate && scheduled) {
      method = SearchMethod::kExact;  // approximate search settled: finish with exact pairs
      previous_rms = std::numeric_limits<double>::infinity();
      continue;
    }
    if (refine && !refining) {
      refining = true;  // converged at the wide bound: tighten it and converge again
      pairing.max_pair_dist_cm = settings.refine_max_pair_dist_cm;
      continue;
    }
    result.world_from_data = orthonormalised(current);
    result.stop = IcpStop::kConverged;
    return result;
  }
  result.world_from_data = orthonormalised(current);
  result.stop = IcpStop::kMaxIterations;
  return result;
}

std::size_t count_pairs(PairingBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                        const WorldModel& model, float max_pair_dist_cm) {
  const ModelPlacement placed{model.cloud, rigid_inverse(model.world_from_model) * world_from_data};
  return static_cast<std::size_t>(
      backend.pair_and_sum(data, {&placed, 1}, SearchMethod::kExact, PairingSettings{max_pair_dist_cm}).count);
}

}  // namespace minemap
