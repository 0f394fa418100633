#pragma once
// Slices of a scan written without "# slice" markers, found from the order of its points. A 2D
// scanner that is tilted or turned between profiles (the paper's) writes each profile's beams one
// after the other, a fraction of a degree apart seen from the scanner, and the next profile starts
// back at the other end of the sweep: between consecutive points of one profile the beam direction
// turns a little, between profiles by most of the sweep. So a new slice starts wherever the
// direction from the scanner (the file's origin) turns by more than break_deg.
//
// Only where that is safe: the slices are kept when the file looks scanner-ordered (within slices
// the median turn is under max_median_step_deg, there are at least min_slices of them, and their
// median length is at least min_median_points), and none are returned otherwise: an unordered
// cloud, a cloud in a world frame, or a rotating multi-beam LiDAR's rings (which turn only a few
// degrees between rings) then stay without slices, as before.
//
// Thread-safety: a pure function. Units: the points' own (only directions matter).
#include <Eigen/Core>
#include <cstdint>
#include <span>
#include <vector>

namespace minemap::io {

struct SliceDetectionSettings {
  double break_deg = 45.0;           ///< a turn from one point to the next beyond this starts a slice
  double max_median_step_deg = 2.0;  ///< scanner order: the median turn within slices is below this
  std::size_t min_slices = 10;
  std::size_t min_median_points = 20;  ///< points in the median slice
};

/// The first point of each slice (0 first), or empty: no slice structure found safely.
std::vector<std::size_t> detect_slice_starts(std::span<const Eigen::Vector3f> points,
                                             const SliceDetectionSettings& settings = {});

}  // namespace minemap::io
