#pragma once
// Rigid poses and 3DTK's conventions (facts: ../shared/notes/FORMATS-3DTK.md).
//
// A pose is an Eigen::Matrix4d T_world_local in double: p_world = R * p_local + t, translation in cm.
// 3DTK stores a pose as x y z (cm) and Euler angles theta_x theta_y theta_z in degrees with
// R = Rx(theta_x) * Ry(theta_y) * Rz(theta_z). Its frame is left-handed: x right, y up, z forward.
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace minemap {

using Pose = Eigen::Matrix4d;

/// 3DTK's `.pose` content: position in cm and Euler angles in degrees.
struct EulerPose {
  Eigen::Vector3d position_cm = Eigen::Vector3d::Zero();
  Eigen::Vector3d angles_deg = Eigen::Vector3d::Zero();  ///< theta_x, theta_y, theta_z
};

/// 3DTK's EulerToMatrix4: R = Rx * Ry * Rz, translation = position.
Pose euler_to_pose(const EulerPose& euler);

/// 3DTK's Matrix4ToEuler, including its gimbal-lock branch (|cos theta_y| <= 0.005).
EulerPose pose_to_euler(const Pose& pose);

/// Inverse of a rigid transform (exact transpose of R, no general inversion).
Pose rigid_inverse(const Pose& pose);

/// Rotation angle of a rigid transform in degrees (angle of R, in [0, 180]).
double rotation_angle_deg(const Pose& pose);

/// Translation length of a rigid transform, in the pose's unit (cm inside minemap).
inline double translation_norm(const Pose& pose) { return pose.block<3, 1>(0, 3).norm(); }

/// A rigid motion as a twist (rotation vector in radians, then translation in the pose's unit),
/// SE(3)'s logarithm: exp(log(T)) = T. For rotation angles below pi.
using Twist = Eigen::Matrix<double, 6, 1>;
/// [v]x, the cross product as a matrix: skew(v) * p = v x p.
Eigen::Matrix3d skew(const Eigen::Vector3d& v);
Twist se3_log(const Pose& pose);
Pose se3_exp(const Twist& twist);

/// The part `fraction` of a motion at constant velocity in its own frame: exp(fraction * log(T))
/// (0: the identity, 1: T, -0.5: half of it backwards). A vehicle turning at a constant rate moves
/// along exactly this screw; the motion model and the deskew take their fractions of a step here.
Pose motion_fraction(const Pose& step, double fraction);

/// Re-orthonormalises the rotation part (polar decomposition through SVD) so that accumulated
/// float or text round-off never yields a non-rotation.
Pose orthonormalised(const Pose& pose);

/// Whether every entry is finite and the rotation part is orthonormal within `tolerance`.
bool is_valid_rigid(const Pose& pose, double tolerance = 1e-6);

/// 3DTK's left-handed cm frame (x right, y up, z forward) from a right-handed metre frame
/// (x forward, y left, z up), as 3DTK's ScanDataTransform_xyz does for points:
/// x_3dtk = -100 y, y_3dtk = 100 z, z_3dtk = 100 x. `scale_to_cm` is 100 for metres, 1 for cm.
Eigen::Vector3d right_handed_to_3dtk(const Eigen::Vector3d& p, double scale_to_cm);
Eigen::Vector3d threedtk_to_right_handed(const Eigen::Vector3d& p_cm, double cm_to_unit);

/// The same change of frame for poses: T_3dtk = C * T_rh * C^-1 (translation scaled).
Pose right_handed_pose_to_3dtk(const Pose& pose, double scale_to_cm);
Pose threedtk_pose_to_right_handed(const Pose& pose_cm, double cm_to_unit);

}  // namespace minemap
