#include "minemap/slam/mapping_result.hpp"

#include <algorithm>

namespace minemap {

bool MappingResult::all_registered() const {
  return std::all_of(scans.begin(), scans.end(), [](const ScanOutcome& s) { return s.registered; });
}

MapPoints MappingResult::map_points(std::size_t i) const {
  const ScanOutcome& scan = scans.at(i);
  if (scan.used_points_cm || !spilled) return {scan.used_points_cm, scan.used_intensity};
  return spilled->points_of(i);
}

std::vector<std::size_t> MappingResult::doubtful() const {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < scans.size(); ++i) {
    if (scans[i].registered && scans[i].health.doubtful()) out.push_back(i);
  }
  return out;
}

}  // namespace minemap
