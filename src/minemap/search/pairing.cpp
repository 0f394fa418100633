// Shared parts of the pairing interface, and the one dispatch point between backends.
#include "minemap/search/pairing.hpp"

#include <cmath>
#include <stdexcept>

#include "minemap/opencl/opencl_backend.hpp"

namespace minemap {

const char* to_string(SearchMethod method) {
  switch (method) {
    case SearchMethod::kExact: return "kd";
    case SearchMethod::kApproximate: return "apx";
    case SearchMethod::kBruteForce: return "brute";
  }
  return "?";
}

SearchMethod parse_search_method(const std::string& text) {
  if (text == "kd" || text == "exact") return SearchMethod::kExact;
  if (text == "apx" || text == "approximate") return SearchMethod::kApproximate;
  if (text == "brute" || text == "bruteforce") return SearchMethod::kBruteForce;
  throw std::invalid_argument("unknown search method '" + text + "' (expected kd, apx or brute)");
}

const char* to_string(Backend backend) {
  switch (backend) {
    case Backend::kAuto: return "auto";
    case Backend::kCpu: return "cpu";
    case Backend::kOpenCl: return "opencl";
  }
  return "?";
}

Backend parse_backend(const std::string& text) {
  if (text == "auto") return Backend::kAuto;
  if (text == "cpu") return Backend::kCpu;
  if (text == "opencl") return Backend::kOpenCl;
  throw std::invalid_argument("unknown backend '" + text + "' (expected auto, cpu or opencl)");
}

double PairSums::rms_cm() const { return count > 0 ? std::sqrt(sum_squared_distance_cm2 / count) : 0.0; }

PairSums& PairSums::operator+=(const PairSums& other) {
  count += other.count;
  sum_data += other.sum_data;
  sum_model += other.sum_model;
  sum_data_model += other.sum_data_model;
  sum_squared_distance_cm2 += other.sum_squared_distance_cm2;
  return *this;
}

void PairSums::add_pair(const Eigen::Vector3f& p, const Eigen::Vector3f& m, float squared_distance_cm2) {
  const double pc[3] = {static_cast<double>(p.x()) - reference_cm.x(), static_cast<double>(p.y()) - reference_cm.y(),
                        static_cast<double>(p.z()) - reference_cm.z()};
  const double mc[3] = {static_cast<double>(m.x()) - reference_cm.x(), static_cast<double>(m.y()) - reference_cm.y(),
                        static_cast<double>(m.z()) - reference_cm.z()};
  count += 1.0;
  for (int r = 0; r < 3; ++r) {
    sum_data[r] += pc[r];
    sum_model[r] += mc[r];
  }
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) sum_data_model(r, c) += pc[r] * mc[c];
  }
  sum_squared_distance_cm2 += static_cast<double>(squared_distance_cm2);
}

PairSums PairSums::from_terms(const double* t, const Eigen::Vector3d& reference_cm) {
  PairSums sums;
  sums.reference_cm = reference_cm;
  sums.count = t[0];
  sums.sum_data = Eigen::Vector3d(t[1], t[2], t[3]);
  sums.sum_model = Eigen::Vector3d(t[4], t[5], t[6]);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) sums.sum_data_model(r, c) = t[7 + 3 * r + c];
  }
  sums.sum_squared_distance_cm2 = t[16];
  return sums;
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

BackendChoice make_pairing_backend(Backend requested) {
  BackendChoice choice;
  if (requested == Backend::kCpu) {
    choice.backend = make_cpu_pairing_backend();
    choice.message = "CPU backend (TBB) as requested";
    return choice;
  }
  std::string why_not;
  auto device = opencl::make_opencl_pairing_backend(requested == Backend::kOpenCl, &why_not);
  if (device) {
    choice.backend = std::move(device);
    choice.message = "OpenCL backend: " + choice.backend->device_description();
    return choice;
  }
  if (requested == Backend::kOpenCl) throw BackendError("OpenCL backend unavailable: " + why_not);
  choice.backend = make_cpu_pairing_backend();
  choice.message = "CPU backend (TBB): " + why_not;
  return choice;
}

}  // namespace minemap
