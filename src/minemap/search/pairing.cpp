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

PreparedCloud::PreparedCloud(std::vector<Eigen::Vector3f> points, const KdTreeSettings& tree_settings)
    : points_(std::move(points)), tree_(points_, tree_settings) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const auto& p : points_) sum += p.cast<double>();
  if (points_.empty()) return;
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
