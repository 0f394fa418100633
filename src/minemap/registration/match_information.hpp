#pragma once
// How well a match pins each direction: the point-to-plane information of its pairs, as 3DTK's LUM
// takes an edge's covariance from the point pairs of its match. A pair on a surface with normal n,
// at data point p, fixes the motion along n: its row of the Jacobian is [n, p x n] for a small
// motion [translation, rotation vector] of the data frame. Summed over the pairs, J^T J says which
// motions the match measured and which it could not see: in a smooth tunnel nothing stops a slide
// along it, and the translation block then has one eigenvalue near zero (a degenerate match).
//
// Units: centimetres and radians. Thread-safety: SurfaceNormals is immutable once built; the
// functions are pure.
#include <Eigen/Core>
#include <cstdint>
#include <span>
#include <unordered_map>
#include <vector>

namespace minemap {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

/// One normal per occupied cubic cell of a cloud (the smallest principal axis of the cell's points),
/// kept only where the cell is a plane: at least 5 points, the smallest spread under a tenth of the
/// middle one. Cells are aligned at the cloud's frame origin.
class SurfaceNormals {
 public:
  SurfaceNormals(std::span<const Eigen::Vector3f> points_cm, float cell_cm);
  /// The normal of the cell holding `point_cm` (cloud frame), or nullptr: no plane there.
  const Eigen::Vector3f* at(const Eigen::Vector3f& point_cm) const;
  std::size_t planes() const { return normals_.size(); }

 private:
  std::int64_t key_of(const Eigen::Vector3f& point_cm) const;
  float inverse_cell_ = 0.0f;
  std::unordered_map<std::int64_t, Eigen::Vector3f> normals_;
};

/// The mean over `points_cm` (data frame) with a plane in `normals` of [n, p x n][n, p x n]^T: the
/// information of one pair, so that matches with different pair counts compare. Zero when no point
/// lies on a plane. `pairs` is set to the number of points that counted.
Matrix6d point_to_plane_information(std::span<const Eigen::Vector3f> points_cm, const SurfaceNormals& normals,
                                    std::size_t* pairs = nullptr);

/// How degenerate the translation of a match is: the smallest eigenvalue of the translation block of
/// `information` over its largest (1: every direction pinned alike; near 0: free to slide along one).
/// `weakest`, when given, gets the direction of the smallest eigenvalue (unit).
double translation_constraint_ratio(const Matrix6d& information, Eigen::Vector3d* weakest = nullptr);

/// How degenerate the turn of a match is: the smallest eigenvalue of the rotation block of
/// `information` over its largest, for turns about axes through the data frame's origin (a sweep's
/// frame is its sensor's). A forward-looking sensor in a tunnel sees walls all round its view axis
/// and hardly a turn about it: the simulated hand-held rosette's is 0.03-0.07, a spinning sensor's
/// 0.4-0.5. `weakest`, when given, gets the axis of the smallest eigenvalue (unit).
double rotation_constraint_ratio(const Matrix6d& information, Eigen::Vector3d* weakest = nullptr);

}  // namespace minemap
