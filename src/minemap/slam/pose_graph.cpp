#include "minemap/slam/pose_graph.hpp"

#include <Eigen/Geometry>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <stdexcept>
#include <string>

namespace minemap {
namespace {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

/// T * Exp(dx): translation in the pose's own frame, rotation by the rotation vector dx.tail<3>().
Pose perturbed(const Pose& pose, const Vector6d& dx) {
  Pose step = Pose::Identity();
  const Eigen::Vector3d phi = dx.tail<3>();
  const double angle = phi.norm();
  if (angle > 0.0) step.block<3, 3>(0, 0) = Eigen::AngleAxisd(angle, phi / angle).toRotationMatrix();
  step.block<3, 1>(0, 3) = dx.head<3>();
  return pose * step;
}

/// The information an edge carries: its own, or the settings' sigmas; times its weight.
Matrix6d information_of(const PoseGraphEdge& e, const Vector6d& isotropic) {
  const Matrix6d information = e.information.isZero() ? Matrix6d(isotropic.asDiagonal()) : e.information;
  return e.weight * information;
}

/// Sum of the squared, weighted residuals.
double cost_of(const std::vector<Pose>& poses, std::span<const PoseGraphEdge> edges, const Vector6d& isotropic) {
  double cost = 0.0;
  for (const PoseGraphEdge& e : edges) {
    const Vector6d r = pose_graph_residual(poses[e.from], poses[e.to], e.from_to);
    cost += r.dot(information_of(e, isotropic) * r);
  }
  return cost;
}

}  // namespace

Eigen::Matrix<double, 6, 1> pose_graph_residual(const Pose& from, const Pose& to, const Pose& from_to) {
  const Pose error = rigid_inverse(from_to) * rigid_inverse(from) * to;
  const Eigen::AngleAxisd rotation(Eigen::Matrix3d(error.block<3, 3>(0, 0)));
  Vector6d r;
  r.head<3>() = error.block<3, 1>(0, 3);
  r.tail<3>() = rotation.angle() * rotation.axis();
  return r;
}

PoseGraphResult optimise_pose_graph(std::vector<Pose> poses, std::span<const PoseGraphEdge> edges, std::size_t fixed,
                                    const PoseGraphSettings& settings) {
  const std::size_t n = poses.size();
  for (const PoseGraphEdge& e : edges) {
    if (!e.information.allFinite() || !(e.weight >= 0.0)) {
      throw std::invalid_argument("pose graph: edge " + std::to_string(e.from) + " -> " + std::to_string(e.to) +
                                  " has a weight or information that is not a finite number >= 0");
    }
    if (e.from >= n || e.to >= n || e.from == e.to) {
      throw std::invalid_argument("pose graph: edge " + std::to_string(e.from) + " -> " + std::to_string(e.to) +
                                  " does not join two of the " + std::to_string(n) + " poses");
    }
  }
  if (fixed >= n) throw std::invalid_argument("pose graph: the fixed pose is not in the graph");
  Vector6d information;
  const double t = 1.0 / (settings.translation_sigma_cm * settings.translation_sigma_cm);
  const double r = 1.0 / (settings.rotation_sigma_rad * settings.rotation_sigma_rad);
  information << t, t, t, r, r, r;

  PoseGraphResult result;
  result.initial_cost = cost_of(poses, edges, information);
  // Unknowns: 6 per pose except the fixed one.
  const auto column = [&](std::size_t node) { return static_cast<int>(6 * (node < fixed ? node : node - 1)); };
  const int unknowns = static_cast<int>(6 * (n - 1));
  if (unknowns == 0 || edges.empty()) {
    result.poses = std::move(poses);
    result.final_cost = result.initial_cost;
    result.converged = true;
    return result;
  }
  // Differentiation steps: small against a step's error, large against rounding.
  constexpr double kStepCm = 1e-4, kStepRad = 1e-7;
  for (int iteration = 0; iteration < settings.max_iterations; ++iteration) {
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(edges.size() * 4 * 36);
    Eigen::VectorXd gradient = Eigen::VectorXd::Zero(unknowns);
    for (const PoseGraphEdge& e : edges) {
      const Vector6d residual = pose_graph_residual(poses[e.from], poses[e.to], e.from_to);
      Matrix6d jacobian_from, jacobian_to;
      for (int k = 0; k < 6; ++k) {
        Vector6d dx = Vector6d::Zero();
        const double h = k < 3 ? kStepCm : kStepRad;
        dx[k] = h;
        jacobian_from.col(k) = (pose_graph_residual(perturbed(poses[e.from], dx), poses[e.to], e.from_to) -
                                pose_graph_residual(perturbed(poses[e.from], -dx), poses[e.to], e.from_to)) /
                               (2.0 * h);
        jacobian_to.col(k) = (pose_graph_residual(poses[e.from], perturbed(poses[e.to], dx), e.from_to) -
                              pose_graph_residual(poses[e.from], perturbed(poses[e.to], -dx), e.from_to)) /
                             (2.0 * h);
      }
      const Matrix6d w = information_of(e, information);
      const std::size_t nodes[2] = {e.from, e.to};
      const Matrix6d* jacobians[2] = {&jacobian_from, &jacobian_to};
      for (int a = 0; a < 2; ++a) {
        if (nodes[a] == fixed) continue;
        gradient.segment<6>(column(nodes[a])) += jacobians[a]->transpose() * (w * residual);
        for (int b = 0; b < 2; ++b) {
          if (nodes[b] == fixed) continue;
          const Matrix6d block = jacobians[a]->transpose() * (w * *jacobians[b]);
          for (int i = 0; i < 6; ++i) {
            for (int j = 0; j < 6; ++j) triplets.emplace_back(column(nodes[a]) + i, column(nodes[b]) + j, block(i, j));
          }
        }
      }
    }
    Eigen::SparseMatrix<double> hessian(unknowns, unknowns);
    hessian.setFromTriplets(triplets.begin(), triplets.end());  // duplicates are summed
    // A pose no edge reaches has an empty block: a unit diagonal keeps it where it is.
    for (int i = 0; i < unknowns; ++i) hessian.coeffRef(i, i) += 1e-9;
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(hessian);
    if (solver.info() != Eigen::Success) break;
    const Eigen::VectorXd step = solver.solve(-gradient);
    if (solver.info() != Eigen::Success || !step.allFinite()) break;
    double largest = 0.0;
    for (std::size_t node = 0; node < n; ++node) {
      if (node == fixed) continue;
      const Vector6d dx = step.segment<6>(column(node));
      poses[node] = orthonormalised(perturbed(poses[node], dx));
      largest = std::max({largest, dx.head<3>().norm(), 100.0 * dx.tail<3>().norm()});
    }
    result.iterations = iteration + 1;
    if (largest < settings.min_update_cm) {
      result.converged = true;
      break;
    }
  }
  result.final_cost = cost_of(poses, edges, information);
  result.poses = std::move(poses);
  return result;
}

}  // namespace minemap
