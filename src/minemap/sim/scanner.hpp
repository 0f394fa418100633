#pragma once
// The beam model of the paper's scanner: a SICK 2D laser (one slice: points_per_slice beams over
// slice_fov_deg, counter-clockwise seen from above, i.e. from the right (+x) through straight ahead
// (+z) to the left (-x)) pitched through tilt_fov_deg in `slices` steps (slice 0 lowest).
//
// Measurement errors, each with its own counter-based random stream per beam:
//   - Gaussian range noise;
//   - mixed pixels: where neighbouring beams see surfaces more than kMixedPixelJumpCm apart, a beam
//     may return a range between the two surfaces (the paper's "salt and pepper" at edges);
//   - reflections: now and then a spurious long or short range;
//   - no return beyond max range, below min range, or where nothing is hit: the beam is ABSENT from
//     its slice, which keeps the scanner order of the remaining points.
//
// Thread-safety: a ScannerModel is immutable after construction; scan_slice() is const and may run
// for different slices (or scans) on any number of threads; the result depends only on its
// arguments, never on the thread or the order.
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace minemap::sim {

class MineWorld;

class ScannerModel {
 public:
  /// Throws std::invalid_argument on non-positive counts or ranges.
  explicit ScannerModel(const ScannerSettings& settings);

  int slices() const { return static_cast<int>(tilt_sin_.size()); }
  int points_per_slice() const { return static_cast<int>(sweep_sin_.size()); }
  /// Tilt of slice i above the horizontal plane (deg), the same in every scan.
  double tilt_deg(int slice) const;
  /// Angle of beam j in its slice, from -fov/2 (right) to +fov/2 (left), deg.
  double sweep_deg(int beam) const;
  /// Unit direction of beam (slice, beam) in the scanner frame (x right, y up, z forward).
  Eigen::Vector3d direction(int slice, int beam) const {
    return {-sweep_sin_[beam], sweep_cos_[beam] * tilt_sin_[slice], sweep_cos_[beam] * tilt_cos_[slice]};
  }

  /// Appends slice `slice` of a scan taken at `T_world_scan` to `out` (scanner frame, cm, scanner
  /// order). `beam_key` selects the random streams (e.g. from seed, scan index and slice).
  void scan_slice(const MineWorld& world, const Pose& T_world_scan, int slice, std::uint64_t beam_key,
                  std::vector<Eigen::Vector3f>& out) const;

  /// True ranges of slice `slice` (infinity where a beam gets no return); no errors added.
  std::vector<double> true_ranges(const MineWorld& world, const Pose& T_world_scan, int slice) const;

  const ScannerSettings& settings() const { return settings_; }

 private:
  ScannerSettings settings_;
  std::vector<double> sweep_sin_, sweep_cos_;
  std::vector<double> tilt_sin_, tilt_cos_;
};

}  // namespace minemap::sim
