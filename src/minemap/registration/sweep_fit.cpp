#include "minemap/registration/sweep_fit.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <vector>

#include <Eigen/Dense>

namespace minemap {

namespace {

// The sweep is cut into this many instants (the deskew cuts it into 4096): a sweep that turns
// 45 deg moves a point 10 m away by 0.4 cm within one.
constexpr int kInstants = 1024;
constexpr double kDerivativeStep = 1e-6;  // rad and cm: exp's central differences at each instant
constexpr int kUnknowns = 12;             // the middle's pose (6), then the motion's twist (6)

double instant_fraction(int k) { return static_cast<double>(k) / kInstants - 0.5; }

int instant_of(float fraction) {
  if (!std::isfinite(fraction)) return kInstants / 2;  // sweep_timing gives none; taken at the middle
  const double f = std::clamp(static_cast<double>(fraction) + 0.5, 0.0, 1.0);
  return static_cast<int>(std::lround(f * kInstants));
}

// The motion from each instant to the sweep's middle, exp(f xi), and its derivatives by the twist
// at that instant (rows: x, y, z; the last column acts on the point's 1).
struct Instants {
  std::vector<Pose> to_middle;
  std::vector<std::array<Eigen::Matrix<double, 3, 4>, 6>> derivative;

  explicit Instants(const Twist& motion) : to_middle(kInstants + 1), derivative(kInstants + 1) {
    for (int k = 0; k <= kInstants; ++k) {
      const auto slot = static_cast<std::size_t>(k);
      const Twist at = instant_fraction(k) * motion;
      to_middle[slot] = se3_exp(at);
      for (int d = 0; d < 6; ++d) {
        Twist step = Twist::Zero();
        step(d) = kDerivativeStep;
        derivative[slot][static_cast<std::size_t>(d)] =
            ((se3_exp(at + step) - se3_exp(at - step)) / (2.0 * kDerivativeStep)).topRows<3>();
      }
    }
  }
};

bool small_change(const Pose& before, const Pose& after, double translation_cm, double rotation_deg) {
  const Pose change = rigid_inverse(before) * after;
  return translation_norm(change) < translation_cm && rotation_angle_deg(change) < rotation_deg;
}

// Whether each of the start, middle and end moved less than the given step.
bool all_small(const std::array<Pose, 3>& before, const std::array<Pose, 3>& after, double translation_cm,
               double rotation_deg) {
  for (std::size_t e = 0; e < 3; ++e) {
    if (!small_change(before[e], after[e], translation_cm, rotation_deg)) return false;
  }
  return true;
}

// The sweep's start, middle and end in the world.
std::array<Pose, 3> ends_of(const Pose& world_from_sweep, const Twist& motion) {
  return {world_from_sweep * se3_exp(-0.5 * motion), world_from_sweep, world_from_sweep * se3_exp(0.5 * motion)};
}

}  // namespace

void SweepFitSettings::validate() const {
  if (!(max_pair_dist_cm > 0.0f) || !std::isfinite(max_pair_dist_cm)) {
    throw std::invalid_argument("sweep fit: the pair bound must be a finite length > 0 cm");
  }
  if (stages < 1 || max_iterations < 1 || min_pairs < kUnknowns) {
    throw std::invalid_argument("sweep fit: stages and iterations must be >= 1, min_pairs >= 12");
  }
  if (!(min_translation_step_cm >= 0.0) || !(min_rotation_step_deg >= 0.0)) {
    throw std::invalid_argument("sweep fit: the least steps must be >= 0");
  }
  if (!(settled_step_cm >= 0.0) || !(settled_step_deg >= 0.0) || settle_iterations < 0) {
    throw std::invalid_argument("sweep fit: the settled steps and iterations must be >= 0");
  }
}

SweepFit fit_sweep(ComputeBackend& backend, std::span<const Eigen::Vector3d> points_cm, std::span<const float> fractions,
                   const WorldModel& model, const SurfaceNormals& model_normals, const Pose& start,
                   const Pose& start_motion, const SweepFitSettings& settings) {
  settings.validate();
  if (fractions.size() != points_cm.size()) throw std::invalid_argument("sweep fit: one fraction per point expected");
  SweepFit fit;
  fit.world_from_sweep = start;
  Twist motion = se3_log(start_motion);
  const Pose model_from_world = rigid_inverse(model.world_from_model);
  const std::span<const Eigen::Vector3f> model_points = model.cloud->points();
  const Eigen::Matrix3d model_to_world = model.world_from_model.block<3, 3>(0, 0);
  // The data cloud is in the world, so the model is placed by its inverse.
  const std::vector<ModelPlacement> placements{{model.cloud, model_from_world, model.skip}};
  const PairingSettings pairing{settings.max_pair_dist_cm, 0.0f};
  std::vector<int> instant(points_cm.size());
  for (std::size_t i = 0; i < points_cm.size(); ++i) instant[i] = instant_of(fractions[i]);

  for (int stage = 1; stage <= settings.stages; ++stage) {
    const double reach = 0.5 * stage / settings.stages;
    std::vector<std::size_t> used;
    for (std::size_t i = 0; i < points_cm.size(); ++i) {
      if (std::abs(instant_fraction(instant[i])) <= reach + 1e-12) used.push_back(i);
    }
    const bool last = stage == settings.stages;
    bool converged = false;
    int settled_for = 0;  // how many iterations in a row moved less than the settled steps
    for (int iteration = 0; iteration < settings.max_iterations && !converged; ++iteration) {
      const Instants instants(motion);
      const Eigen::Matrix3d rotation = fit.world_from_sweep.block<3, 3>(0, 0);
      const Eigen::Vector3d translation = fit.world_from_sweep.block<3, 1>(0, 3);
      // Each used point at the sweep's middle, and in the world where the fit puts it.
      std::vector<Eigen::Vector3d> at_middle(used.size());
      std::vector<Eigen::Vector3f> world(used.size());
      for (std::size_t u = 0; u < used.size(); ++u) {
        const Pose& to_middle = instants.to_middle[static_cast<std::size_t>(instant[used[u]])];
        at_middle[u] = to_middle.block<3, 3>(0, 0) * points_cm[used[u]] + to_middle.block<3, 1>(0, 3);
        world[u] = (rotation * at_middle[u] + translation).cast<float>();
      }
      const std::shared_ptr<const PreparedCloud> data =
          backend.prepare(std::move(world), KdTreeSettings{}, TreeBuild::kOnFirstUse);
      const std::vector<NearestPair> pairs = backend.nearest(*data, placements, SearchMethod::kExact, pairing);
      // Gauss-Newton's normal equations on n . (x - m), summed in point order (deterministic).
      Eigen::Matrix<double, kUnknowns, kUnknowns> normal = Eigen::Matrix<double, kUnknowns, kUnknowns>::Zero();
      Eigen::Matrix<double, kUnknowns, 1> gradient = Eigen::Matrix<double, kUnknowns, 1>::Zero();
      double squared = 0.0;
      std::size_t paired = 0;
      for (std::size_t u = 0; u < used.size(); ++u) {
        if (pairs[u].squared_distance_cm2 < 0.0f || pairs[u].model_point < 0) continue;
        const Eigen::Vector3d matched = pairs[u].position_cm.cast<double>();
        // The plane of the model point's own cell (its coordinates as the model holds them).
        const Eigen::Vector3f* plane = model_normals.at(model_points[static_cast<std::size_t>(pairs[u].model_point)]);
        if (plane == nullptr) continue;
        const Eigen::Vector3d n = model_to_world * plane->cast<double>();
        const double residual = n.dot(rotation * at_middle[u] + translation - matched);
        // d x / d(middle's twist), then d x / d(motion's twist) = f d x / d(the instant's twist).
        Eigen::Matrix<double, 1, kUnknowns> row;
        const Eigen::RowVector3d n_rotated = n.transpose() * rotation;
        row.segment<3>(0) = -n_rotated * skew(at_middle[u]);
        row.segment<3>(3) = n_rotated;
        const std::size_t k = static_cast<std::size_t>(instant[used[u]]);
        const double f = instant_fraction(instant[used[u]]);
        for (int d = 0; d < 6; ++d) {
          const Eigen::Matrix<double, 3, 4>& by = instants.derivative[k][static_cast<std::size_t>(d)];
          row(6 + d) = f * n_rotated.dot(by.leftCols<3>() * points_cm[used[u]] + by.col(3));
        }
        normal.noalias() += row.transpose() * row;
        gradient.noalias() += row.transpose() * residual;
        squared += residual * residual;
        ++paired;
      }
      fit.pairs = paired;
      fit.rms_cm = paired > 0 ? std::sqrt(squared / static_cast<double>(paired)) : 0.0;
      if (paired < static_cast<std::size_t>(settings.min_pairs)) {
        // A part of the sweep that sees too little of the model (the middle facing the vehicle)
        // leaves the fit where it is; the next stage sees more. The last stage fails.
        if (!last) break;
        fit.motion = se3_exp(motion);
        return fit;
      }
      // A direction no pair measures gets no motion (point_to_plane.cpp's damping).
      Eigen::Matrix<double, kUnknowns, kUnknowns> damped = normal;
      damped.diagonal() += 1e-6 * normal.diagonal();
      const Eigen::Matrix<double, kUnknowns, 1> step = damped.ldlt().solve(-gradient);
      if (!step.allFinite()) {
        fit.motion = se3_exp(motion);
        return fit;
      }
      const std::array<Pose, 3> before = ends_of(fit.world_from_sweep, motion);
      fit.world_from_sweep = orthonormalised(fit.world_from_sweep * se3_exp(step.head<6>()));
      motion += step.tail<6>();
      ++fit.iterations;
      const std::array<Pose, 3> after = ends_of(fit.world_from_sweep, motion);
      converged = all_small(before, after, settings.min_translation_step_cm, settings.min_rotation_step_deg);
      settled_for = all_small(before, after, settings.settled_step_cm, settings.settled_step_deg) ? settled_for + 1 : 0;
    }
    // An earlier stage may end unconverged: the next goes on from there. The last, at its cap, may
    // have settled (the pairs' churn), which is as far as its pairs take it.
    fit.settled = last && !converged && settings.settle_iterations > 0 && settled_for >= settings.settle_iterations;
    fit.converged = converged || fit.settled;
  }
  fit.motion = se3_exp(motion);
  return fit;
}

}  // namespace minemap
