// ICP as the paper writes it (section IV.A), in phases; see icp.hpp for the schedule.
#include "minemap/registration/icp.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <vector>

#include "minemap/registration/anderson_acceleration.hpp"
#include "minemap/registration/horn.hpp"
#include "minemap/registration/point_to_plane.hpp"

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

void IcpSettings::validate() const {
  if (!(max_pair_dist_cm > 0.0f) || !std::isfinite(max_pair_dist_cm)) {
    throw std::invalid_argument("the pair bound must be a finite distance > 0 cm");
  }
  if (!(refine_pair_dist_fraction >= 0.0f && refine_pair_dist_fraction < 1.0f)) {
    throw std::invalid_argument("the refinement's pair bound must be a fraction in [0, 1) of the pair bound (0 = off)");
  }
  if (termination.max_iterations < 1) throw std::invalid_argument("the ICP iteration cap must be >= 1");
  if (!(termination.min_translation_step_cm >= 0.0) || !(termination.min_rotation_step_deg >= 0.0)) {
    throw std::invalid_argument("ICP's convergence steps must be >= 0");
  }
  if (termination.min_pairs < 0) throw std::invalid_argument("ICP's minimum pair count must be >= 0");
  if (acceleration_history < 1) throw std::invalid_argument("the acceleration history must be >= 1");
  if (!(robust_scale_fraction >= 0.0f) || !std::isfinite(robust_scale_fraction)) {
    throw std::invalid_argument("the robust kernel's scale must be a finite fraction >= 0 of the pair bound (0 = off)");
  }
}

namespace {

/// One pairing as ICP's loop reads it, whichever the objective: the backend's point-to-point sums,
/// or the point-to-plane system summed on the host from the backend's pairs.
struct Pairing {
  PairSums sums;
  PlaneSums plane;
  bool planar = false;
  double count() const { return planar ? plane.count : sums.count; }
  double rms_cm() const { return planar ? plane.rms_cm() : sums.rms_cm(); }
  /// The objective's sum over the pairs (squared distances, or the planes' residuals).
  double residual_cm2() const { return planar ? plane.sum_squared_residual_cm2 : sums.sum_squared_distance_cm2; }
};

/// How a phase ended. kErrorRose: the approximate phase stopped because E(R, t) stopped falling.
enum class PhaseEnd { kConverged, kErrorRose, kIterationCap, kFailed };

/// One registration in progress: the pose, the pairing, and the result so far. The phases below
/// are its methods, each a loop of the paper's step.
class IcpRun {
 public:
  IcpRun(ComputeBackend& backend, const PreparedCloud& data, const Pose& start, std::span<const WorldModel> models,
         const IcpSettings& settings, std::span<const Eigen::Vector3f> data_normals)
      : backend_(backend),
        data_(data),
        models_(models),
        settings_(settings),
        data_normals_(data_normals),
        start_(start),
        pose_(start),
        min_pairs_(std::max(3, settings.termination.min_pairs)),
        frame_{data.centroid_cm(),
               std::max(1.0, 0.5 * (data.bounds_max() - data.bounds_min()).cast<double>().norm())} {
    result_.world_from_data = start;
  }

  /// Phase 1: the approximate kd-tree while the error falls. It ends when a step is small, or when
  /// the RMS pair distance stops falling (that pairing is discarded: the exact phase redoes it).
  PhaseEnd approximate() {
    double previous_rms = std::numeric_limits<double>::infinity();
    for (bool first = true; budget_left(); first = false) {
      const Pairing sums = pair(SearchMethod::kApproximate, settings_.max_pair_dist_cm);
      if (sums.count() < min_pairs_) return fail(IcpStop::kTooFewPairs, sums);
      if (!first && !(sums.rms_cm() < previous_rms)) return PhaseEnd::kErrorRose;
      previous_rms = sums.rms_cm();
      const auto step = horn_step(sums);
      if (!step) return fail(IcpStop::kNumericFailure, sums);
      if (!take(*step, sums, result_.approximate_iterations)) return fail(IcpStop::kNumericFailure, sums);
      if (small(*step)) return PhaseEnd::kConverged;
    }
    return PhaseEnd::kIterationCap;
  }

  /// Phases 2 and 3: exact search (or brute force) at `bound_cm` until a step is small. With
  /// acceleration, every plain step is followed by an extrapolated jump; the next pairing judges
  /// it by ICP's objective, and a jump that did not lower it is taken back. The accelerator
  /// measures poses from `origin` (its linearisation point; a rejected jump moves it to the pose
  /// kept).
  PhaseEnd exact(SearchMethod method, float bound_cm, bool refining, const Pose& origin) {
    detail::AndersonAccelerator accelerator(frame_, settings_.acceleration_history);
    accelerator.reset(origin);
    bool jumped = false;
    Pose plain_pose = pose_;  // where the last plain step landed, before the jump
    double objective_before_jump = 0.0;
    while (budget_left()) {
      const Pairing sums = pair(method, bound_cm);
      const double objective = objective_of(sums, bound_cm);
      if (jumped) {
        jumped = false;
        if (!(objective < objective_before_jump) || sums.count() < min_pairs_) {
          pose_ = plain_pose;  // take the jump back; its pairing is the cost
          --result_.accelerations;
          ++result_.rejected_accelerations;
          ++result_.exact_iterations;
          accelerator.reset(pose_);
          continue;
        }
      } else if (sums.count() < min_pairs_) {
        return fail(IcpStop::kTooFewPairs, sums);
      }
      const auto step = horn_step(sums);
      if (!step) return fail(IcpStop::kNumericFailure, sums);
      const Pose before = pose_;
      if (!take(*step, sums, result_.exact_iterations)) return fail(IcpStop::kNumericFailure, sums);
      if (refining) ++result_.refine_iterations;
      if (small(*step)) return PhaseEnd::kConverged;
      if (!settings_.accelerate) continue;
      const Pose accelerated = accelerator.next(before, pose_);
      if (accelerated.isApprox(pose_, 0.0)) continue;
      plain_pose = pose_;
      objective_before_jump = objective;
      pose_ = accelerated;
      jumped = true;
      ++result_.accelerations;
    }
    return PhaseEnd::kIterationCap;
  }

  /// The result after the phases: converged, or stopped at the cap with the last pose.
  IcpResult finish(IcpStop stop) {
    result_.world_from_data = orthonormalised(pose_);
    result_.stop = stop;
    return result_;
  }
  /// The result after a failed phase (the initial pose, and why).
  const IcpResult& failed() const { return result_; }
  const Pose& pose() const { return pose_; }

 private:
  bool budget_left() const { return result_.iterations() < settings_.termination.max_iterations; }

  /// Pair and sum at the current pose: the closest model point of every data point within the
  /// bound, over the union of the models.
  Pairing pair(SearchMethod method, float bound_cm) {
    placed_.clear();
    for (const auto& m : models_) placed_.push_back({m.cloud, rigid_inverse(m.world_from_model) * pose_, m.skip});
    Pairing pairing;
    if (settings_.objective == IcpObjective::kPointToPlane) {
      pairing.planar = true;
      pairing.plane = backend_.pair_and_plane_sum(data_, placed_, method, PairingSettings{bound_cm}, data_normals_);
      return pairing;
    }
    pairing.sums = backend_.pair_and_sum(data_, placed_, method,
                                         PairingSettings{bound_cm, bound_cm * settings_.robust_scale_fraction});
    return pairing;
  }

  /// ICP's objective with the pair bound: every data point costs its squared pair distance, or the
  /// bound squared when unpaired. Unlike the RMS over pairs (pairs come and go), a plain ICP step
  /// never raises it, so it can judge a jump.
  double objective_of(const Pairing& sums, float bound_cm) const {
    const double bound = bound_cm;
    return sums.residual_cm2() + (static_cast<double>(data_.points().size()) - sums.count()) * bound * bound +
           start_spring_energy();
  }

  /// Horn's closed form for the pairs: the rigid step (data frame) that minimises E(R, t); or the
  /// point-to-plane system's step.
  std::optional<Pose> horn_step(const Pairing& sums) const {
    auto step = sums.planar ? plane_step(sums.plane) : horn_transform(with_start_spring(sums.sums));
    if (step && !is_valid_rigid(*step, 1e-6)) step.reset();
    return step;
  }

  /// The sums with the spring to the start added (IcpSettings::start_spring_pairs): the data
  /// frame's origin paired with where the start puts it, both in the data frame at the current pose,
  /// centred on the sums' reference as every pair is.
  PairSums with_start_spring(const PairSums& sums) const {
    const double weight = settings_.start_spring_pairs;
    if (!(weight > 0.0)) return sums;
    PairSums with = sums;
    const Eigen::Vector3d data = -with.reference_cm;  // the origin
    const Eigen::Vector3d model = (rigid_inverse(pose_) * start_).block<3, 1>(0, 3) - with.reference_cm;
    with.sum_data += weight * data;
    with.sum_model += weight * model;
    with.sum_data_model += weight * data * model.transpose();
    with.weight += weight;
    return with;
  }
  /// The spring's energy at the current pose: its weight times its squared length (cm^2).
  double start_spring_energy() const {
    const double weight = settings_.start_spring_pairs;
    if (!(weight > 0.0)) return 0.0;
    return weight * (rigid_inverse(pose_) * start_).block<3, 1>(0, 3).squaredNorm();
  }

  /// Composes the step onto the pose and counts the iteration; false when the pose is not finite.
  bool take(const Pose& step, const Pairing& sums, int& phase_iterations) {
    pose_ = pose_ * step;
    ++phase_iterations;
    result_.pairs = static_cast<std::size_t>(sums.count());
    result_.rms_cm = sums.rms_cm();
    return pose_.allFinite();
  }

  bool small(const Pose& step) const {
    return translation_norm(step) < settings_.termination.min_translation_step_cm &&
           rotation_angle_deg(step) < settings_.termination.min_rotation_step_deg;
  }

  PhaseEnd fail(IcpStop why, const Pairing& sums) {
    result_.stop = why;
    if (why == IcpStop::kTooFewPairs) result_.pairs = static_cast<std::size_t>(sums.count());
    result_.world_from_data = start_;
    return PhaseEnd::kFailed;
  }

  ComputeBackend& backend_;
  const PreparedCloud& data_;
  std::span<const WorldModel> models_;
  const IcpSettings& settings_;
  std::span<const Eigen::Vector3f> data_normals_;
  Pose start_, pose_;
  double min_pairs_;
  detail::MotionFrame frame_;
  std::vector<ModelPlacement> placed_;
  IcpResult result_;
};

}  // namespace

IcpResult register_icp(ComputeBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                       std::span<const WorldModel> models, const IcpSettings& settings,
                       std::span<const Eigen::Vector3f> data_normals) {
  if (settings.objective == IcpObjective::kPointToPlane && data_normals.size() != data.points().size()) {
    throw std::invalid_argument("point-to-plane ICP needs one normal per data point");
  }
  IcpRun run(backend, data, world_from_data, models, settings, data_normals);
  const SearchMethod exact = settings.method == SearchMethod::kBruteForce ? SearchMethod::kBruteForce : SearchMethod::kExact;
  const float refine_bound = settings.refine_max_pair_dist_cm();
  const bool refine = refine_bound > 0.0f && refine_bound < settings.max_pair_dist_cm;

  // The first exact phase measures accelerated poses from where the approximate phase converged,
  // or from the start when that phase ended because the error rose (its last steps were not
  // trusted). This is the origin minemap has always used (docs/benchmarks.md compares it with
  // re-centring there too).
  PhaseEnd end = PhaseEnd::kConverged;
  if (settings.method == SearchMethod::kApproximate) end = run.approximate();
  if (end == PhaseEnd::kConverged || end == PhaseEnd::kErrorRose) {
    const Pose origin = end == PhaseEnd::kErrorRose ? world_from_data : run.pose();
    end = run.exact(exact, settings.max_pair_dist_cm, /*refining=*/false, origin);
  }
  if (end == PhaseEnd::kConverged && refine) end = run.exact(exact, refine_bound, /*refining=*/true, run.pose());
  switch (end) {
    case PhaseEnd::kConverged:
    case PhaseEnd::kErrorRose: return run.finish(IcpStop::kConverged);
    case PhaseEnd::kIterationCap: return run.finish(IcpStop::kMaxIterations);
    case PhaseEnd::kFailed: break;
  }
  return run.failed();
}

std::size_t count_pairs(ComputeBackend& backend, const PreparedCloud& data, const Pose& world_from_data,
                        const WorldModel& model, float max_pair_dist_cm) {
  const ModelPlacement placed{model.cloud, rigid_inverse(model.world_from_model) * world_from_data, model.skip};
  return static_cast<std::size_t>(
      backend.pair_and_sum(data, {&placed, 1}, SearchMethod::kExact, PairingSettings{max_pair_dist_cm}).count);
}

}  // namespace minemap
