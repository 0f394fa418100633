#pragma once
// Internal to src/minemap/io: checks shared by every reader that takes a pose from text (.frames,
// 4x4 matrices, KITTI, TUM, graph, PCD VIEWPOINT). Implemented in trajectories.cpp.
#include <Eigen/Core>

#include "minemap/core/pose.hpp"
#include "minemap/io/text_reader.hpp"

namespace minemap::io::detail {

/// How far a rotation read from text may be from orthonormal (and a quaternion from unit norm).
/// Files written with 6 significant digits (3DTK .frames, KITTI) are off by ~1e-6; 1e-3 still
/// catches a transposed, scaled or garbled matrix.
inline constexpr double kRotationTolerance = 1e-3;

/// `raw` checked to be rigid (finite, orthonormal rotation with determinant +1, last row 0 0 0 1,
/// all within kRotationTolerance) and re-orthonormalised; fails at the reader's current line.
Pose checked_rigid_pose(const Pose& raw, const LineReader& reader);

/// Pose from a translation in cm and a quaternion (w, x, y, z) whose norm must be 1 within
/// kRotationTolerance; the quaternion is normalised.
Pose pose_from_quaternion(const Eigen::Vector3d& translation_cm, double qw, double qx, double qy, double qz,
                          const LineReader& reader);

}  // namespace minemap::io::detail
