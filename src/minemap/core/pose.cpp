#include "minemap/core/pose.hpp"

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <numbers>

namespace minemap {
namespace {
constexpr double kDegPerRad = 180.0 / std::numbers::pi;

// C maps right-handed (x fwd, y left, z up) axes onto 3DTK's (x right, y up, z fwd): a reflection.
Eigen::Matrix3d right_handed_to_3dtk_axes() {
  Eigen::Matrix3d c;
  c << 0, -1, 0,  //
      0, 0, 1,    //
      1, 0, 0;
  return c;
}
}  // namespace

Pose euler_to_pose(const EulerPose& euler) {
  const Eigen::Vector3d rad = euler.angles_deg / kDegPerRad;
  const double sx = std::sin(rad.x()), cx = std::cos(rad.x());
  const double sy = std::sin(rad.y()), cy = std::cos(rad.y());
  const double sz = std::sin(rad.z()), cz = std::cos(rad.z());
  Pose m = Pose::Identity();
  // Row-major reading of 3DTK's column-major EulerToMatrix4.
  m(0, 0) = cy * cz;
  m(0, 1) = -cy * sz;
  m(0, 2) = sy;
  m(1, 0) = sx * sy * cz + cx * sz;
  m(1, 1) = -sx * sy * sz + cx * cz;
  m(1, 2) = -sx * cy;
  m(2, 0) = -cx * sy * cz + sx * sz;
  m(2, 1) = cx * sy * sz + sx * cz;
  m(2, 2) = cx * cy;
  m.block<3, 1>(0, 3) = euler.position_cm;
  return m;
}

EulerPose pose_to_euler(const Pose& m) {
  // 3DTK's column-major indices: M[0]=m(0,0), M[1]=m(1,0), M[4]=m(0,1), M[5]=m(1,1),
  // M[8]=m(0,2), M[9]=m(1,2), M[10]=m(2,2).
  EulerPose out;
  const double m8 = std::clamp(m(0, 2), -1.0, 1.0);
  double theta_y = m(0, 0) > 0 ? std::asin(m8) : std::numbers::pi - std::asin(m8);
  const double c = std::cos(theta_y);
  double theta_x = 0.0;
  double theta_z = 0.0;
  if (std::abs(c) > 0.005) {
    theta_x = std::atan2(-m(1, 2) / c, m(2, 2) / c);
    theta_z = std::atan2(-m(0, 1) / c, m(0, 0) / c);
  } else {
    theta_x = 0.0;
    theta_z = std::atan2(m(1, 0), m(1, 1));
  }
  out.angles_deg = Eigen::Vector3d(theta_x, theta_y, theta_z) * kDegPerRad;
  out.position_cm = m.block<3, 1>(0, 3);
  return out;
}

Pose rigid_inverse(const Pose& pose) {
  Pose inv = Pose::Identity();
  const Eigen::Matrix3d rt = pose.block<3, 3>(0, 0).transpose();
  inv.block<3, 3>(0, 0) = rt;
  inv.block<3, 1>(0, 3) = -rt * pose.block<3, 1>(0, 3);
  return inv;
}

double rotation_angle_deg(const Pose& pose) {
  const double cos_angle = std::clamp((pose.block<3, 3>(0, 0).trace() - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(cos_angle) * kDegPerRad;
}

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

namespace {

/// SE(3)'s left Jacobian V(omega): t = V * rho. Series near zero, where the closed form cancels.
Eigen::Matrix3d left_jacobian(const Eigen::Vector3d& omega) {
  const double theta = omega.norm();
  const Eigen::Matrix3d w = skew(omega);
  if (theta < 1e-5) return Eigen::Matrix3d::Identity() + 0.5 * w + (1.0 / 6.0) * w * w;
  const double t2 = theta * theta;
  return Eigen::Matrix3d::Identity() + (1.0 - std::cos(theta)) / t2 * w + (theta - std::sin(theta)) / (t2 * theta) * w * w;
}

}  // namespace

Twist se3_log(const Pose& pose) {
  const Eigen::AngleAxisd angle_axis(Eigen::Matrix3d(pose.block<3, 3>(0, 0)));
  const Eigen::Vector3d omega = angle_axis.angle() * angle_axis.axis();
  Twist twist;
  twist.head<3>() = omega;
  twist.tail<3>() = left_jacobian(omega).inverse() * pose.block<3, 1>(0, 3);
  return twist;
}

Pose se3_exp(const Twist& twist) {
  const Eigen::Vector3d omega = twist.head<3>();
  Pose pose = Pose::Identity();
  const double theta = omega.norm();
  pose.block<3, 3>(0, 0) = theta > 0.0 ? Eigen::AngleAxisd(theta, omega / theta).toRotationMatrix()
                                       : Eigen::Matrix3d::Identity();
  pose.block<3, 1>(0, 3) = left_jacobian(omega) * twist.tail<3>();
  return pose;
}

Pose motion_fraction(const Pose& step, double fraction) {
  if (fraction == 1.0) return step;
  if (fraction == 0.0) return Pose::Identity();
  return se3_exp(fraction * se3_log(step));
}

Pose orthonormalised(const Pose& pose) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(pose.block<3, 3>(0, 0), Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d r = svd.matrixU() * svd.matrixV().transpose();
  if (r.determinant() < 0) {
    Eigen::Matrix3d u = svd.matrixU();
    u.col(2) *= -1.0;
    r = u * svd.matrixV().transpose();
  }
  Pose out = pose;
  out.block<3, 3>(0, 0) = r;
  out.row(3) << 0, 0, 0, 1;
  return out;
}

bool is_valid_rigid(const Pose& pose, double tolerance) {
  if (!pose.allFinite()) return false;
  const Eigen::Matrix3d r = pose.block<3, 3>(0, 0);
  if (!(r * r.transpose()).isApprox(Eigen::Matrix3d::Identity(), tolerance)) return false;
  if (std::abs(r.determinant() - 1.0) > tolerance) return false;
  return std::abs(pose(3, 0)) + std::abs(pose(3, 1)) + std::abs(pose(3, 2)) + std::abs(pose(3, 3) - 1.0) <= tolerance;
}

Eigen::Vector3d right_handed_to_3dtk(const Eigen::Vector3d& p, double scale_to_cm) {
  return right_handed_to_3dtk_axes() * p * scale_to_cm;
}

Eigen::Vector3d threedtk_to_right_handed(const Eigen::Vector3d& p_cm, double cm_to_unit) {
  return right_handed_to_3dtk_axes().transpose() * p_cm * cm_to_unit;
}

Pose right_handed_pose_to_3dtk(const Pose& pose, double scale_to_cm) {
  const Eigen::Matrix3d c = right_handed_to_3dtk_axes();
  Pose out = Pose::Identity();
  out.block<3, 3>(0, 0) = c * pose.block<3, 3>(0, 0) * c.transpose();
  out.block<3, 1>(0, 3) = c * pose.block<3, 1>(0, 3) * scale_to_cm;
  return out;
}

Pose threedtk_pose_to_right_handed(const Pose& pose_cm, double cm_to_unit) {
  const Eigen::Matrix3d c = right_handed_to_3dtk_axes();
  Pose out = Pose::Identity();
  out.block<3, 3>(0, 0) = c.transpose() * pose_cm.block<3, 3>(0, 0) * c;
  out.block<3, 1>(0, 3) = c.transpose() * pose_cm.block<3, 1>(0, 3) * cm_to_unit;
  return out;
}

}  // namespace minemap
