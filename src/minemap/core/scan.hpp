#pragma once
// The scan model: one 3D scan as the paper's tilting 2D scanner records it.
#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "minemap/core/pose.hpp"

namespace minemap {

/// The attributes a point may carry beside its coordinates, as bits of a mask (ReadSettings::attributes).
enum PointAttribute : std::uint8_t {
  kIntensity = 1,     ///< PCD intensity / i, PLY intensity / scalar_intensity, KITTI's 4th value, uos reflectance
  kColour = 2,        ///< PCD rgb / rgba, PLY red green blue
  kTime = 4,          ///< per-point time in seconds: PCD time / t / timestamp, PLY time
  kRing = 8,          ///< the laser's ring (beam): PCD ring / PLY ring
  kReturnNumber = 16, ///< the return of a multi-return sensor (LAS)
};
inline constexpr std::uint8_t kAllPointAttributes = kIntensity | kColour | kTime | kRing | kReturnNumber;

/// One point's attribute values, as a reader hands them to the scan (only the columns the scan
/// keeps are stored).
struct PointValues {
  float intensity = 0.0f;
  std::uint32_t rgb = 0;  ///< 0xRRGGBB
  double time_s = 0.0;
  std::uint16_t ring = 0;
  std::uint8_t return_number = 0;
};

/// What the points carry beside their coordinates: one column per attribute, in the order of
/// Scan::points_cm, or empty when the file has none (or the reader was not asked to keep it): an
/// absent attribute costs nothing. The matching never reads them; the exports and the 3D view do.
/// Thread-safety: a plain value.
struct PointAttributes {
  std::vector<float> intensity;             ///< as the file stores it (no scaling)
  std::vector<std::uint32_t> rgb;           ///< 0xRRGGBB
  std::vector<double> time_s;               ///< seconds, as the file's clock counts them
  std::vector<std::uint16_t> ring;
  std::vector<std::uint8_t> return_number;

  /// The mask of the columns held (PointAttribute bits).
  std::uint8_t columns() const {
    return static_cast<std::uint8_t>((intensity.empty() ? 0 : kIntensity) | (rgb.empty() ? 0 : kColour) |
                                     (time_s.empty() ? 0 : kTime) | (ring.empty() ? 0 : kRing) |
                                     (return_number.empty() ? 0 : kReturnNumber));
  }
  /// Appends one point's values to the columns of `mask`.
  void push_back(const PointValues& values, std::uint8_t mask) {
    if (mask & kIntensity) intensity.push_back(values.intensity);
    if (mask & kColour) rgb.push_back(values.rgb);
    if (mask & kTime) time_s.push_back(values.time_s);
    if (mask & kRing) ring.push_back(values.ring);
    if (mask & kReturnNumber) return_number.push_back(values.return_number);
  }
  /// Point i's values (0 where a column is absent).
  PointValues at(std::size_t i) const {
    PointValues values;
    if (!intensity.empty()) values.intensity = intensity[i];
    if (!rgb.empty()) values.rgb = rgb[i];
    if (!time_s.empty()) values.time_s = time_s[i];
    if (!ring.empty()) values.ring = ring[i];
    if (!return_number.empty()) values.return_number = return_number[i];
    return values;
  }
};

/// One 3D scan: points in the scan's local frame (float, cm) and a 6-DoF pose (double).
///
/// Slices: a tilting 2D scanner records the scan as ordered 2D slices (the paper: 341 slices of up
/// to 361 points), each slice's points in scanner order. `slice_offsets` holds num_slices + 1
/// offsets into `points_cm`; it is empty for scans without slice structure (PCD, PLY, KITTI), which
/// skip the slice filter but are otherwise first-class. No-return beams are absent from a slice.
///
/// Local frame: points are stored relative to `local_origin_cm` (a point of the file's frame), so a
/// cloud 1 km from its file's origin keeps full float resolution. T_world_file is `pose_cm`;
/// T_world_points is `world_from_points()`. Readers pick the origin; near-origin scans keep zero.
///
/// Thread-safety: a plain value type; concurrent reads are safe, writes need external locking.
struct Scan {
  std::string name;         ///< e.g. "scan003"; used to name outputs
  std::string source_path;  ///< where it was read from, for messages (may be empty)
  std::vector<Eigen::Vector3f> points_cm;
  std::vector<std::uint32_t> slice_offsets;
  Eigen::Vector3d local_origin_cm = Eigen::Vector3d::Zero();
  Pose pose_cm = Pose::Identity();  ///< T_world_file: initial guess (odometry) or registered pose
  PointAttributes attributes;       ///< per point, beside points_cm (each column empty or of its size)

  bool has_slices() const { return slice_offsets.size() >= 2; }
  std::size_t num_slices() const { return has_slices() ? slice_offsets.size() - 1 : 0; }
  std::size_t size() const { return points_cm.size(); }
  bool empty() const { return points_cm.empty(); }

  /// Points of slice `i` in scanner order.
  std::span<const Eigen::Vector3f> slice(std::size_t i) const {
    return {points_cm.data() + slice_offsets[i], points_cm.data() + slice_offsets[i + 1]};
  }

  /// T_world_points = pose_cm * Translation(local_origin_cm).
  Pose world_from_points() const;

  /// Sets pose_cm so that world_from_points() equals `world_from_points`.
  void set_world_from_points(const Pose& world_from_points);

  /// Point `i` in the file's frame, in double.
  Eigen::Vector3d file_point(std::size_t i) const { return points_cm[i].cast<double>() + local_origin_cm; }

  /// Moves the local origin to the points' centroid when the centroid lies farther than
  /// `threshold_cm` from it (float coordinates lose resolution far from their origin).
  void recentre_if_far(double threshold_cm = 10000.0);

  /// Throws std::invalid_argument if slice offsets are inconsistent or a point is not finite.
  void validate() const;
};

/// Axis-aligned bounds of a point set, in the frame of the points.
struct Bounds3d {
  Eigen::Vector3d min_cm = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d max_cm = Eigen::Vector3d::Constant(-std::numeric_limits<double>::infinity());
  bool empty() const { return !(min_cm.array() <= max_cm.array()).all(); }
  void extend(const Eigen::Vector3d& p) {
    min_cm = min_cm.cwiseMin(p);
    max_cm = max_cm.cwiseMax(p);
  }
  bool intersects(const Bounds3d& other, double margin_cm) const {
    return !empty() && !other.empty() &&
           ((min_cm.array() - margin_cm) <= other.max_cm.array()).all() &&
           ((other.min_cm.array() - margin_cm) <= max_cm.array()).all();
  }
};

/// World-frame bounds of `points` placed by `world_from_points` (the 8 corners of the local box).
Bounds3d world_bounds(std::span<const Eigen::Vector3f> points, const Pose& world_from_points);

}  // namespace minemap
