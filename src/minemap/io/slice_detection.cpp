#include "minemap/io/slice_detection.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace minemap::io {

std::vector<std::size_t> detect_slice_starts(std::span<const Eigen::Vector3f> points,
                                             const SliceDetectionSettings& settings) {
  const double break_cos = std::cos(settings.break_deg * std::numbers::pi / 180.0);
  std::vector<std::size_t> starts{0};
  std::vector<double> steps_cos;  // the turns within slices, as cosines (larger: a smaller turn)
  steps_cos.reserve(points.size());
  Eigen::Vector3d previous = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < points.size(); ++k) {
    const Eigen::Vector3d p = points[k].cast<double>();
    const double range = p.norm();
    if (!(range > 0.0)) continue;  // a point on the scanner has no direction: it joins the slice it is in
    const Eigen::Vector3d direction = p / range;
    if (previous != Eigen::Vector3d::Zero()) {
      const double turn_cos = direction.dot(previous);
      if (turn_cos < break_cos) {
        starts.push_back(k);
      } else {
        steps_cos.push_back(turn_cos);
      }
    }
    previous = direction;
  }
  if (starts.size() < settings.min_slices || steps_cos.empty()) return {};
  std::vector<std::size_t> lengths;
  lengths.reserve(starts.size());
  for (std::size_t s = 0; s < starts.size(); ++s) {
    lengths.push_back((s + 1 < starts.size() ? starts[s + 1] : points.size()) - starts[s]);
  }
  const auto median_of = [](auto values) {
    std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
    return values[values.size() / 2];
  };
  if (median_of(lengths) < settings.min_median_points) return {};
  const double median_cos = median_of(steps_cos);
  if (median_cos < std::cos(settings.max_median_step_deg * std::numbers::pi / 180.0)) return {};
  return starts;
}

}  // namespace minemap::io
