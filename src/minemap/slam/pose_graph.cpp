#include "minemap/slam/pose_graph.hpp"

#include <Eigen/Geometry>
#include <Eigen/SparseCholesky>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
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
  return optimise_pose_graph(std::move(poses), edges, {}, {}, fixed, settings);
}

namespace {

Eigen::Vector3d prior_residual(const PoseGraphPrior& p, const Pose& pose) {
  return pose.block<3, 3>(0, 0) * p.point_cm + pose.block<3, 1>(0, 3) - p.position_cm;
}

double rotation_residual(const PoseGraphRotationPrior& p, const Pose& pose) {
  const Eigen::AngleAxisd turn(Eigen::Matrix3d(pose.block<3, 3>(0, 0) * p.known.transpose()));
  return p.axis_world.dot(turn.angle() * turn.axis());
}

/// One graph's normal equations: its poses' unknowns (6 a pose but the fixed one's) and terms.
struct Graph {
  std::span<const PoseGraphEdge> edges;
  std::span<const PoseGraphPrior> priors;
  std::span<const PoseGraphRotationPrior> rotation_priors;
  std::size_t fixed;
  std::size_t n;
  Vector6d isotropic;  ///< the settings' information, for an edge without its own

  bool pinned_by_priors() const { return fixed == kNoFixedPose; }
  int column(std::size_t node) const { return static_cast<int>(6 * (pinned_by_priors() || node < fixed ? node : node - 1)); }
  int unknowns() const { return static_cast<int>(6 * (pinned_by_priors() ? n : n - 1)); }

  double cost(const std::vector<Pose>& at) const {
    double cost = cost_of(at, edges, isotropic);
    for (const PoseGraphPrior& p : priors) {
      const Eigen::Vector3d e = prior_residual(p, at[p.node]);
      cost += e.dot(p.information * e);
    }
    for (const PoseGraphRotationPrior& p : rotation_priors) {
      const double e = rotation_residual(p, at[p.node]);
      cost += p.information * e * e;
    }
    return cost;
  }

  /// J^T W J (hessian) and J^T W r (gradient) at `at`, Jacobians by central differences.
  void assemble(const std::vector<Pose>& at, Eigen::SparseMatrix<double>& hessian, Eigen::VectorXd& gradient) const {
    // Differentiation steps: small against a step's error, large against rounding.
    constexpr double kStepCm = 1e-4, kStepRad = 1e-7;
    const int size = unknowns();
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(edges.size() * 4 * 36 + (priors.size() + rotation_priors.size()) * 36);
    gradient = Eigen::VectorXd::Zero(size);
    for (const PoseGraphEdge& e : edges) {
      const Vector6d residual = pose_graph_residual(at[e.from], at[e.to], e.from_to);
      Matrix6d jacobian_from, jacobian_to;
      for (int k = 0; k < 6; ++k) {
        Vector6d dx = Vector6d::Zero();
        const double h = k < 3 ? kStepCm : kStepRad;
        dx[k] = h;
        jacobian_from.col(k) = (pose_graph_residual(perturbed(at[e.from], dx), at[e.to], e.from_to) -
                                pose_graph_residual(perturbed(at[e.from], -dx), at[e.to], e.from_to)) /
                               (2.0 * h);
        jacobian_to.col(k) = (pose_graph_residual(at[e.from], perturbed(at[e.to], dx), e.from_to) -
                              pose_graph_residual(at[e.from], perturbed(at[e.to], -dx), e.from_to)) /
                             (2.0 * h);
      }
      const Matrix6d w = information_of(e, isotropic);
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
    // The priors: one pose each.
    const auto add_unary = [&](std::size_t node, const Eigen::MatrixXd& jacobian, const Eigen::MatrixXd& w,
                               const Eigen::VectorXd& residual) {
      if (node == fixed) return;
      gradient.segment<6>(column(node)) += jacobian.transpose() * (w * residual);
      const Matrix6d block = jacobian.transpose() * (w * jacobian);
      for (int i = 0; i < 6; ++i) {
        for (int j = 0; j < 6; ++j) triplets.emplace_back(column(node) + i, column(node) + j, block(i, j));
      }
    };
    for (const PoseGraphPrior& p : priors) {
      Eigen::Matrix<double, 3, 6> jacobian;
      for (int k = 0; k < 6; ++k) {
        Vector6d dx = Vector6d::Zero();
        const double h = k < 3 ? kStepCm : kStepRad;
        dx[k] = h;
        jacobian.col(k) =
            (prior_residual(p, perturbed(at[p.node], dx)) - prior_residual(p, perturbed(at[p.node], -dx))) / (2.0 * h);
      }
      add_unary(p.node, jacobian, p.information, prior_residual(p, at[p.node]));
    }
    for (const PoseGraphRotationPrior& p : rotation_priors) {
      Eigen::Matrix<double, 1, 6> jacobian;
      for (int k = 0; k < 6; ++k) {
        Vector6d dx = Vector6d::Zero();
        const double h = k < 3 ? kStepCm : kStepRad;
        dx[k] = h;
        jacobian(0, k) =
            (rotation_residual(p, perturbed(at[p.node], dx)) - rotation_residual(p, perturbed(at[p.node], -dx))) /
            (2.0 * h);
      }
      add_unary(p.node, jacobian, Eigen::Matrix<double, 1, 1>(p.information),
                Eigen::Matrix<double, 1, 1>(rotation_residual(p, at[p.node])));
    }
    hessian.resize(size, size);
    hessian.setFromTriplets(triplets.begin(), triplets.end());  // duplicates are summed
    // A pose no edge reaches has an empty block: a unit diagonal keeps it where it is.
    for (int i = 0; i < size; ++i) hessian.coeffRef(i, i) += 1e-9;
  }

  /// The marginal covariances of `nodes` at `at`: blocks of the inverse normal matrix, six solves a
  /// node on one factorisation (in parallel; each solve reads the factor only).
  std::vector<Matrix6d> covariances(const std::vector<Pose>& at, std::span<const std::size_t> nodes) const {
    Eigen::SparseMatrix<double> hessian;
    Eigen::VectorXd gradient;
    assemble(at, hessian, gradient);
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(hessian);
    std::vector<Matrix6d> result(nodes.size(), Matrix6d::Zero());
    if (solver.info() != Eigen::Success) return result;
    const int size = unknowns();
    tbb::parallel_for(std::size_t{0}, nodes.size(), [&](std::size_t k) {
      const std::size_t node = nodes[k];
      if (node == fixed) return;
      Eigen::MatrixXd unit = Eigen::MatrixXd::Zero(size, 6);
      for (int c = 0; c < 6; ++c) unit(column(node) + c, c) = 1.0;
      const Eigen::MatrixXd columns = solver.solve(unit);
      const Matrix6d block = columns.middleRows<6>(column(node));
      result[k] = 0.5 * (block + block.transpose());
    });
    return result;
  }
};

/// Checks the graph's terms against its poses (std::invalid_argument).
void check_graph(std::size_t n, std::span<const PoseGraphEdge> edges, std::span<const PoseGraphPrior> priors,
                 std::span<const PoseGraphRotationPrior> rotation_priors, std::size_t fixed) {
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
  for (const PoseGraphPrior& p : priors) {
    if (p.node >= n || !p.point_cm.allFinite() || !p.position_cm.allFinite() || !p.information.allFinite()) {
      throw std::invalid_argument("pose graph: a prior on pose " + std::to_string(p.node) +
                                  " names no pose of the graph or is not finite");
    }
  }
  for (const PoseGraphRotationPrior& p : rotation_priors) {
    if (p.node >= n || !p.known.allFinite() || !p.axis_world.allFinite() || !std::isfinite(p.information)) {
      throw std::invalid_argument("pose graph: a rotation prior on pose " + std::to_string(p.node) +
                                  " names no pose of the graph or is not finite");
    }
  }
  if (fixed != kNoFixedPose && fixed >= n) throw std::invalid_argument("pose graph: the fixed pose is not in the graph");
}

Vector6d isotropic_information(const PoseGraphSettings& settings) {
  Vector6d information;
  const double t = 1.0 / (settings.translation_sigma_cm * settings.translation_sigma_cm);
  const double r = 1.0 / (settings.rotation_sigma_rad * settings.rotation_sigma_rad);
  information << t, t, t, r, r, r;
  return information;
}

}  // namespace

PoseGraphResult optimise_pose_graph(std::vector<Pose> poses, std::span<const PoseGraphEdge> edges,
                                    std::span<const PoseGraphPrior> priors,
                                    std::span<const PoseGraphRotationPrior> rotation_priors, std::size_t fixed,
                                    const PoseGraphSettings& settings) {
  const std::size_t n = poses.size();
  check_graph(n, edges, priors, rotation_priors, fixed);
  const Graph graph{edges, priors, rotation_priors, fixed, n, isotropic_information(settings)};
  PoseGraphResult result;
  result.initial_cost = graph.cost(poses);
  const bool unary = !priors.empty() || !rotation_priors.empty();
  std::vector<std::size_t> all(n);
  for (std::size_t k = 0; k < n; ++k) all[k] = k;
  if (graph.unknowns() == 0 || (edges.empty() && !unary)) {
    result.final_cost = result.initial_cost;
    result.converged = true;
    if (settings.covariances) result.covariances.assign(n, Matrix6d::Zero());
    result.poses = std::move(poses);
    return result;
  }
  // Levenberg-Marquardt (PoseGraphSettings::damped): each step solves (H + lambda diag(H)) dx = -g
  // and is kept only when it lowers the cost; lambda falls after a kept step and rises after a
  // refused one. Plain Gauss-Newton (lambda 0, every step kept) otherwise.
  double lambda = settings.damped ? 1e-4 : 0.0;
  double cost = settings.damped ? result.initial_cost : 0.0;
  for (int iteration = 0; iteration < settings.max_iterations; ++iteration) {
    Eigen::SparseMatrix<double> hessian;
    Eigen::VectorXd gradient;
    graph.assemble(poses, hessian, gradient);
    bool done = false;
    for (int attempt = 0; attempt < (settings.damped ? 12 : 1); ++attempt) {
      Eigen::SparseMatrix<double> damped = hessian;
      if (lambda > 0.0) {
        for (int i = 0; i < damped.rows(); ++i) damped.coeffRef(i, i) *= 1.0 + lambda;
      }
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(damped);
      if (solver.info() != Eigen::Success) {
        done = true;
        break;
      }
      const Eigen::VectorXd step = solver.solve(-gradient);
      if (solver.info() != Eigen::Success || !step.allFinite()) {
        done = true;
        break;
      }
      std::vector<Pose> moved = poses;
      double largest = 0.0;
      for (std::size_t node = 0; node < n; ++node) {
        if (node == fixed) continue;
        const Vector6d dx = step.segment<6>(graph.column(node));
        moved[node] = orthonormalised(perturbed(poses[node], dx));
        largest = std::max({largest, dx.head<3>().norm(), 100.0 * dx.tail<3>().norm()});
      }
      if (settings.damped) {
        const double moved_cost = graph.cost(moved);
        if (!(moved_cost <= cost)) {  // refused: a smaller step
          lambda *= 10.0;
          if (largest < settings.min_update_cm) {
            result.converged = true;
            done = true;
            break;
          }
          continue;
        }
        cost = moved_cost;
        lambda = std::max(lambda / 10.0, 1e-12);
      }
      poses = std::move(moved);
      result.iterations = iteration + 1;
      if (largest < settings.min_update_cm) {
        result.converged = true;
        done = true;
      }
      break;
    }
    if (done) break;
  }
  result.final_cost = graph.cost(poses);
  if (settings.covariances) result.covariances = graph.covariances(poses, all);
  result.poses = std::move(poses);
  return result;
}

std::vector<Eigen::Matrix<double, 6, 6>> pose_graph_covariances(const std::vector<Pose>& poses,
                                                                std::span<const PoseGraphEdge> edges,
                                                                std::span<const PoseGraphPrior> priors,
                                                                std::span<const PoseGraphRotationPrior> rotation_priors,
                                                                std::size_t fixed, const PoseGraphSettings& settings,
                                                                std::span<const std::size_t> nodes) {
  check_graph(poses.size(), edges, priors, rotation_priors, fixed);
  for (const std::size_t node : nodes) {
    if (node >= poses.size()) throw std::invalid_argument("pose graph: a covariance of a pose not in the graph");
  }
  const Graph graph{edges, priors, rotation_priors, fixed, poses.size(), isotropic_information(settings)};
  if (graph.unknowns() == 0) return std::vector<Matrix6d>(nodes.size(), Matrix6d::Zero());
  return graph.covariances(poses, nodes);
}

}  // namespace minemap
