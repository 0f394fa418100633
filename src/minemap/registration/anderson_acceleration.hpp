#pragma once
// Internal (not installed): Anderson acceleration of ICP's fixed-point iteration, used by the exact
// phases of register_icp (icp.cpp) when IcpSettings::accelerate is on.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/QR>
#include <algorithm>
#include <vector>

#include "minemap/core/pose.hpp"

namespace minemap::detail {

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
}  // namespace minemap::detail
