#include "minemap/slam/pose_errors.hpp"

#include <algorithm>
#include <stdexcept>

namespace minemap {

PoseErrors pose_errors(const std::vector<Pose>& estimated, const std::vector<Pose>& reference) {
  if (estimated.size() != reference.size() || estimated.empty()) {
    throw std::invalid_argument("pose_errors: estimated and reference differ in count or are empty");
  }
  PoseErrors errors;
  const Pose est0 = rigid_inverse(estimated.front());
  const Pose ref0 = rigid_inverse(reference.front());
  const std::size_t n = estimated.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Pose difference = rigid_inverse(ref0 * reference[i]) * (est0 * estimated[i]);
    const double t = translation_norm(difference), r = rotation_angle_deg(difference);
    errors.mean_translation_cm += t / static_cast<double>(n);
    errors.mean_rotation_deg += r / static_cast<double>(n);
    errors.max_translation_cm = std::max(errors.max_translation_cm, t);
    errors.max_rotation_deg = std::max(errors.max_rotation_deg, r);
    if (i == 0) continue;
    const Pose relative_ref = rigid_inverse(reference[i - 1]) * reference[i];
    const Pose relative_est = rigid_inverse(estimated[i - 1]) * estimated[i];
    const Pose relative_difference = rigid_inverse(relative_ref) * relative_est;
    const double rt = translation_norm(relative_difference), rr = rotation_angle_deg(relative_difference);
    errors.mean_relative_translation_cm += rt / static_cast<double>(n - 1);
    errors.mean_relative_rotation_deg += rr / static_cast<double>(n - 1);
    errors.max_relative_translation_cm = std::max(errors.max_relative_translation_cm, rt);
    errors.max_relative_rotation_deg = std::max(errors.max_relative_rotation_deg, rr);
    errors.path_length_cm += translation_norm(relative_ref);
  }
  return errors;
}

}  // namespace minemap
