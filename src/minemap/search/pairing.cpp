// Search methods by name, and the prepared cloud.
#include "minemap/search/pairing.hpp"

#include <cmath>
#include <stdexcept>

namespace minemap {

const char* to_string(SearchMethod method) { return name_in(kSearchMethodNames, method); }

SearchMethod parse_search_method(const std::string& text) {
  if (const auto alias = value_named(kSearchMethodAliases, text)) return *alias;
  return parse_named(kSearchMethodNames, text, "search method");
}

void require_exact_search_for_skips(std::span<const ModelPlacement> models, SearchMethod method) {
  if (method == SearchMethod::kExact) return;
  for (const ModelPlacement& model : models) {
    if (model.skip.count > 0) {
      throw std::invalid_argument(
          std::string("model points are left out (ModelPlacement::skip) only by the exact search, not ") +
          to_string(method));
    }
  }
}

PreparedCloud::PreparedCloud(std::vector<Eigen::Vector3f> points, const KdTreeSettings& tree_settings,
                             TreeBuild when)
    : points_(std::move(points)), tree_settings_(tree_settings) {
  if (when == TreeBuild::kNow) tree();
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& p : points_) sum += p.cast<double>();
  if (points_.empty()) return;
  bounds_min_ = bounds_max_ = points_[0];
  for (const auto& p : points_) {
    bounds_min_ = bounds_min_.cwiseMin(p);
    bounds_max_ = bounds_max_.cwiseMax(p);
  }
  // Rounded to float so that a device, which centres in float, subtracts exactly this reference.
  const Eigen::Vector3d centroid = sum / static_cast<double>(points_.size());
  // Through a volatile float: GCC 12's SLP vectorizer drops a plain double->float->double round
  // trip on two of the three lanes (seen at -O2 and -O3), which would leave x and y unrounded.
  for (int d = 0; d < 3; ++d) {
    volatile float rounded = static_cast<float>(centroid[d]);
    centroid_cm_[d] = rounded;
  }
}

}  // namespace minemap
