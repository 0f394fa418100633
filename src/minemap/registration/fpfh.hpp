#pragma once
// Fast Point Feature Histograms (Rusu, Blodow and Beetz, ICRA 2009): a 33-number description of
// the surface shape around a point that does not depend on where the scan stands, so two scans of
// the same place can be paired without a start (registration/global_registration.hpp). A cloud is
// thinned to one point per cube (the mean of its points), each point gets the normal of its
// neighbours' plane (PCA, turned toward the viewpoint), and each point's histogram counts how the
// normals of its neighbours turn against its own (three angles of the Darboux frame, 11 bins each),
// averaged with its neighbours' own histograms, weighted by 1 / distance^2.
//
// Units: cm, as every cloud inside minemap. Thread-safety: a pure function; parallel inside
// (TBB, one output slot per point: the same bits for any thread count).
#include <Eigen/Core>
#include <array>
#include <span>
#include <vector>

namespace minemap {

/// How clouds are described. The radii scale with the cube: a surface must hold enough thinned
/// points for a plane (normal radius) and a shape (feature radius); the defaults are the usual
/// 2x and 5x of the cube (Open3D's and PCL's examples), sized for a mine's drives and a street.
struct FeatureSettings {
  float voxel_cm = 50.0f;               ///< one point (the mean) per cube of this size
  float normal_radius_voxels = 2.0f;    ///< the plane of the neighbours within this many cubes
  float feature_radius_voxels = 5.0f;   ///< the histogram over the neighbours within this many cubes
  float normal_radius_cm() const { return normal_radius_voxels * voxel_cm; }
  float feature_radius_cm() const { return feature_radius_voxels * voxel_cm; }
  int min_normal_neighbours = 5;     ///< fewer neighbours (itself included): no normal, no feature
  /// Throws std::invalid_argument naming the bad setting.
  void validate() const;
  bool operator==(const FeatureSettings&) const = default;
};

inline constexpr int kFpfhBins = 33;  ///< 3 angles x 11 bins
using Fpfh = std::array<float, kFpfhBins>;

/// A cloud described: the thinned points that have a normal and a histogram (index k of each).
struct FeatureCloud {
  std::vector<Eigen::Vector3f> points_cm;
  std::vector<Eigen::Vector3f> normals;  ///< unit, turned toward the viewpoint
  /// Each 11-bin block sums to 200: 100 the point's own histogram, 100 its neighbours' weighted
  /// mean (0 for a point with no neighbour).
  std::vector<Fpfh> features;
  std::size_t size() const { return points_cm.size(); }
};

/// The points of `points_cm`, one mean per cube of voxel_cm (cubes [k c, (k+1) c)), in the order
/// their cubes are first met: the same cloud for the same input.
std::vector<Eigen::Vector3f> cube_means(std::span<const Eigen::Vector3f> points_cm, float voxel_cm);

/// The three angles of the pair (p, n_p), (q, n_q) as the FPFH paper defines them, in PCL's order:
/// {theta = atan2(w . n_t, n_s . n_t) in [-pi, pi], alpha = v . n_t, phi = u . (q - p) / |q - p|},
/// the source s the one whose normal makes the smaller angle with the line between them. false when
/// the points coincide or the normal is along the line (no frame).
bool pair_angles(const Eigen::Vector3f& p, const Eigen::Vector3f& n_p, const Eigen::Vector3f& q,
                 const Eigen::Vector3f& n_q, std::array<float, 3>& angles);

/// Thins `points_cm`, estimates normals (turned toward `viewpoint_cm`, the sensor's position in the
/// cloud's frame) and computes every kept point's FPFH.
FeatureCloud describe_fpfh(std::span<const Eigen::Vector3f> points_cm, const Eigen::Vector3f& viewpoint_cm,
                           const FeatureSettings& settings);

}  // namespace minemap
