#include "minemap/registration/icp.hpp"

#include <Eigen/Geometry>
#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
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

using Motion = Eigen::Matrix<double, 6, 1>;

/// Besl and McKay's state change as one 6-vector in cm: how far an ICP step (data frame) moves the
/// data centroid, and its rotation vector times the cloud's radius (so that turning and moving
/// weigh alike wherever the data frame's origin is).
struct MotionFrame {
  Eigen::Vector3d centroid_cm;
  double radius_cm;

  Motion of(const Pose& step) const {
    const Eigen::Matrix3d rotation = step.block<3, 3>(0, 0);
    const Eigen::AngleAxisd turn(rotation);
    Motion motion;
    motion.head<3>() = rotation * centroid_cm + step.block<3, 1>(0, 3) - centroid_cm;
    motion.tail<3>() = turn.angle() * turn.axis() * radius_cm;
    return motion;
  }
  Pose step(const Motion& motion) const {
    const Eigen::Vector3d rotation_vector = motion.tail<3>() / radius_cm;
    const double angle = rotation_vector.norm();
    const Eigen::Matrix3d rotation =
        angle > 0.0 ? Eigen::AngleAxisd(angle, rotation_vector / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
    Pose step = Pose::Identity();
    step.block<3, 3>(0, 0) = rotation;
    step.block<3, 1>(0, 3) = centroid_cm + motion.head<3>() - rotation * centroid_cm;
    return step;
  }
};

/// Anderson acceleration of the ICP fixed-point map x -> G(x) (Walker and Ni 2011; for ICP,
/// Pavlov et al., "AA-ICP", 2018). x is the pose as a Motion from a fixed anchor pose. From the last
/// few plain results g_i = G(x_i) and residuals f_i = g_i - x_i, the next point is
///   x_next = g_k - dG theta,  theta = argmin |f_k - dF theta|,
/// dF, dG: differences of consecutive f and g. For ICP creeping along a shallow valley, where each
/// step shrinks by a near-constant factor, this extrapolates to the valley's end.
class AndersonAccelerator {
 public:
  AndersonAccelerator(const MotionFrame& frame, int history) : frame_(frame), history_(std::max(1, history)) {}

  void reset(const Pose& anchor) {
    anchor_ = anchor;
    g_.clear();
    f_.clear();
  }
  bool empty() const { return g_.empty(); }

  /// Records one plain ICP step from `before` to `after`; returns the accelerated pose.
  Pose next(const Pose& before, const Pose& after) {
    const Motion x = frame_.of(rigid_inverse(anchor_) * before);
    const Motion g = frame_.of(rigid_inverse(anchor_) * after);
    g_.push_back(g);
    f_.push_back(g - x);
    if (static_cast<int>(g_.size()) > history_ + 1) {
      g_.erase(g_.begin());
      f_.erase(f_.begin());
    }
    const int columns = static_cast<int>(g_.size()) - 1;
    if (columns == 0) return after;
    Eigen::Matrix<double, 6, Eigen::Dynamic> df(6, columns), dg(6, columns);
    for (int c = 0; c < columns; ++c) {
      df.col(c) = f_[c + 1] - f_[c];
      dg.col(c) = g_[c + 1] - g_[c];
    }
    const Eigen::VectorXd theta = df.completeOrthogonalDecomposition().solve(f_.back());
    const Motion accelerated = g_.back() - dg * theta;
    if (!accelerated.allFinite()) return after;
    return anchor_ * frame_.step(accelerated);
  }

 private:
  MotionFrame frame_;
  int history_;
  Pose anchor_ = Pose::Identity();
  std::vector<Motion> g_, f_;
};
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

  // Acceleration (exact search only): the accelerator, and the plain result a jump must beat.
  const MotionFrame frame{data.centroid_cm(),
                          std::max(1.0, 0.5 * (data.tree().bounds_max() - data.tree().bounds_min()).cast<double>().norm())};
  AndersonAccelerator accelerator(frame, settings.acceleration_history);
  accelerator.reset(current);
  bool jumped = false;
  Pose plain_result = current;
  double energy_before_jump = 0.0;

  for (int iteration = 0; iteration < settings.max_iterations; ++iteration) {
    const auto placed = place(models, current);
    const PairSums sums = backend.pair_and_sum(data, placed, method, pairing);
    if (sums.count < std::max(3, settings.min_pairs) && !jumped) {
      result.stop = IcpStop::kTooFewPairs;
      result.pairs = static_cast<std::size_t>(sums.count);
      result.world_from_data = world_from_data;
      return result;
    }
    const double rms = sums.rms_cm();
    // ICP's own objective with the pair bound: every data point costs its squared pair distance,
    // or the bound squared when unpaired. Unlike the RMS over pairs (pairs come and go), a plain
    // ICP step never raises it, so it can judge a jump.
    const double bound = pairing.max_pair_dist_cm;
    const double energy =
        sums.sum_squared_distance_cm2 + (static_cast<double>(data.points().size()) - sums.count) * bound * bound;
    if (jumped) {
      jumped = false;
      // The objective must fall below the one the last plain step started from;
      // otherwise the jump left the valley: take it back (this pairing pass was the cost).
      if (!(energy < energy_before_jump) || sums.count < std::max(3, settings.min_pairs)) {
        current = plain_result;
        --result.accelerations;
        ++result.rejected_accelerations;
        ++result.exact_iterations;
        accelerator.reset(current);
        continue;
      }
    }
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
    const Pose before_step = current;
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
    if (!small_step) {
      if (settings.accelerate && method == SearchMethod::kExact) {
        const Pose accelerated = accelerator.next(before_step, current);
        if (!accelerated.isApprox(current, 0.0)) {
          plain_result = current;
          energy_before_jump = energy;
          current = accelerated;
          jumped = true;
          ++result.accelerations;
        }
      }
      continue;
    }
    accelerator.reset(current);  // a new phase (exact search, a tighter bound) starts afresh
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
