#include "minemap/filter/deskew.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace minemap {

const char* to_string(DeskewMode mode) { return name_in(kDeskewModeNames, mode); }
DeskewMode parse_deskew_mode(const std::string& text) { return parse_named(kDeskewModeNames, text, "deskew"); }

namespace {
constexpr int kFractionSteps = 4096;  // across the sweep, from -0.5 to 0.5
}

SweepTiming sweep_timing(const Scan& scan, double max_sweep_s) {
  SweepTiming timing;
  const std::vector<double>& times = scan.attributes.time_s;
  if (times.empty() || times.size() != scan.size()) return timing;
  const auto [low, high] = std::minmax_element(times.begin(), times.end());
  const double duration = *high - *low;
  if (!(duration > 0.0) || !std::isfinite(duration) || duration > max_sweep_s) return timing;
  timing.stamp_s = 0.5 * (*low + *high);
  timing.duration_s = duration;
  timing.fraction.resize(times.size());
  for (std::size_t i = 0; i < times.size(); ++i) {
    timing.fraction[i] = static_cast<float>(std::clamp((times[i] - timing.stamp_s) / duration, -0.5, 0.5));
  }
  return timing;
}

std::vector<Eigen::Vector3f> deskewed_points(const Scan& scan, const SweepTiming& timing, const Pose& sweep_motion) {
  if (timing.empty()) return scan.points_cm;
  // One motion per step of the sweep: exp(f log T) for the step's fraction.
  std::vector<Pose> motion(kFractionSteps + 1);
  const Twist twist = se3_log(sweep_motion);
  for (int k = 0; k <= kFractionSteps; ++k) {
    const double fraction = static_cast<double>(k) / kFractionSteps - 0.5;
    motion[static_cast<std::size_t>(k)] = se3_exp(fraction * twist);
  }
  // Points are stored relative to the scan's local origin, a point of the file's (the sensor's)
  // frame: p_file = p + o moves to R p_file + t, stored again relative to o.
  const Eigen::Vector3d origin = scan.local_origin_cm;
  std::vector<Eigen::Vector3f> out(scan.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, scan.size(), 4096), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const double f = static_cast<double>(timing.fraction[i]) + 0.5;
      const auto k = static_cast<std::size_t>(std::lround(std::clamp(f, 0.0, 1.0) * kFractionSteps));
      const Pose& t = motion[k];
      const Eigen::Vector3d p = scan.points_cm[i].cast<double>() + origin;
      out[i] = (t.block<3, 3>(0, 0) * p + t.block<3, 1>(0, 3) - origin).cast<float>();
    }
  });
  return out;
}

}  // namespace minemap
