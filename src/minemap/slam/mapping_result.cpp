#include "minemap/slam/mapping_result.hpp"

#include <algorithm>

namespace minemap {

bool MappingResult::all_registered() const {
  return std::all_of(scans.begin(), scans.end(), [](const ScanOutcome& s) { return s.registered; });
}

std::vector<std::size_t> MappingResult::doubtful() const {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < scans.size(); ++i) {
    if (scans[i].registered && scans[i].health.doubtful()) out.push_back(i);
  }
  return out;
}

}  // namespace minemap
