#pragma once
// Slice filtering and data reduction (paper, section IV.C), per 2D slice in scanner order:
//  1. median filter: a point whose range differs from the median range of its window (n = 7
//     neighbours by index) by more than 200 cm is replaced by the median point (salt and pepper);
//  2. reduction: consecutive points closer than 10 cm are joined into their mean, so consecutive
//     output points of a slice are at least 10 cm apart (lowers Gaussian noise);
//  3. vertical reduction: only every third slice goes to matching.
//
// Backends: the CPU reference (slice_filter_cpu.cpp, TBB over slices; CpuBackend runs it) and
// OpenCL (kernels/slice_filter.cl, one work-item per slice; OpenClBackend). ComputeBackend::
// filter_slices is how mapping reaches either. Both compute in float in the same order (the shared
// steps are in minemap/shared/minemap_shared.h) and give the same bits on every test input.
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "minemap/core/scan.hpp"
#include "minemap/shared/minemap_shared.h"

namespace minemap {

/// Thread-safety: a plain value.
struct SliceFilterSettings {
  bool median_enabled = true;
  int median_window = 7;                  ///< points in the window, odd, 1..kMaxMedianWindow (paper: n = 7)
  float outlier_threshold_cm = 200.0f;    ///< replace only beyond this range difference (paper: 200 cm)
  bool reduction_enabled = true;
  float min_point_spacing_cm = 10.0f;     ///< consecutive reduced points at least this far apart
  int slice_stride = 3;                   ///< keep slices 0, stride, 2*stride, ... (paper: every third)

  /// Throws std::invalid_argument naming the bad setting.
  void validate() const;
  bool operator==(const SliceFilterSettings&) const = default;
};

/// The widest median window the kernels hold (MM_MAX_MEDIAN_WINDOW).
inline constexpr int kMaxMedianWindow = MM_MAX_MEDIAN_WINDOW;

/// What the filter did, and its output cloud.
struct SliceFilterResult {
  std::vector<Eigen::Vector3f> points_cm;     ///< reduced points, kept slices in order
  std::vector<std::uint32_t> slice_offsets;   ///< output slices (one per kept slice)
  std::size_t points_in = 0;                  ///< all points of the scan
  std::size_t points_in_kept_slices = 0;
  std::size_t outliers_replaced = 0;
  std::size_t points_out() const { return points_cm.size(); }
  std::string backend;                        ///< "cpu" or "opencl"
};

/// The result for a scan without slices: its points unchanged, as one output slice.
SliceFilterResult unfiltered_result(const Scan& scan, const std::string& backend);

/// Indices of the slices that go to matching: 0, stride, 2 * stride, ...
std::vector<std::size_t> kept_slice_indices(const Scan& scan, const SliceFilterSettings& settings);

/// The CPU reference (what CpuBackend runs), for tests and oracles. Validates `settings` (throws
/// std::invalid_argument); a scan without slices is returned unchanged.
SliceFilterResult filter_scan_cpu(const Scan& scan, const SliceFilterSettings& settings);

/// Scans without slice structure (PCD, KITTI, PLY) skip the slice filter; matching uses them
/// after this uniform thinning instead: every `stride`-th point (1 = all points).
std::vector<Eigen::Vector3f> thin_unstructured(const Scan& scan, int stride);

}  // namespace minemap
