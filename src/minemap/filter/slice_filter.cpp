// The slice filter's settings check: the one place its limits are stated.
#include "minemap/filter/slice_filter.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace minemap {

void SliceFilterSettings::validate() const {
  if (median_window < 1 || median_window > kMaxMedianWindow || median_window % 2 == 0) {
    throw std::invalid_argument("median window must be odd and within 1.." + std::to_string(kMaxMedianWindow) +
                                ", got " + std::to_string(median_window));
  }
  if (!(outlier_threshold_cm >= 0.0f)) throw std::invalid_argument("outlier threshold must be >= 0 cm");
  if (!(min_point_spacing_cm >= 0.0f) || !std::isfinite(min_point_spacing_cm)) {
    throw std::invalid_argument("minimum point spacing must be a finite length >= 0 cm");
  }
  if (slice_stride < 1) throw std::invalid_argument("slice stride must be >= 1");
}

}  // namespace minemap
