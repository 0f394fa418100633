#include "minemap/slam/relaxation.hpp"

#include <stdexcept>

namespace minemap::detail {

void Relaxation::queue_first(std::size_t i) {
  queued_.resize(i + 1, false);  // no scan before it could queue it
  queue_.push_front(i);
  queued_[i] = true;
}

void Relaxation::restore_queue(const std::vector<std::size_t>& queue, std::size_t scans) {
  queue_.assign(queue.begin(), queue.end());
  queued_.assign(scans, false);
  for (const std::size_t j : queue_) {
    if (j >= scans) throw std::invalid_argument("a queued scan beyond the scans restored");
    queued_[j] = true;
  }
}

std::vector<std::size_t> Relaxation::neighbours(const SurveyState& state, std::size_t current,
                                                std::size_t newest) const {
  const std::size_t max_neighbours = static_cast<std::size_t>(settings_.max_relaxation_neighbours);
  const float bound = settings_.icp.max_pair_dist_cm;
  std::vector<std::size_t> found;
  for (const std::size_t j : state.nearby(current, state.pose(current), newest + 1, double(bound))) {
    if (max_neighbours > 0 && found.size() == max_neighbours) break;
    const WorldModel model{state.prepared(j).model_cloud.get(), state.pose(j)};
    const std::size_t pairs = count_pairs(backend_, *state.prepared(current).cloud, state.pose(current), model, bound);
    if (pairs > static_cast<std::size_t>(settings_.min_overlap_pairs)) found.push_back(j);
  }
  return found;
}

Relaxation::Tally Relaxation::relax(SurveyState& state, std::size_t newest, int budget, const RunControl& control) {
  const double grow_cm = double(registration_.icp().max_pair_dist_cm) + settings_.metascan_margin_cm;
  Tally tally;
  while (!queue_.empty() && tally.matches < budget && !control.stop_requested()) {
    const std::size_t current = queue_.front();
    queue_.pop_front();
    queued_[current] = false;
    const std::vector<std::size_t> near = neighbours(state, current, newest);
    if (near.empty()) continue;
    const Pose before = state.pose(current);
    const auto metascan = local_map_.union_of(state, current, near, before, before, grow_cm);
    const std::vector<WorldModel> models{{metascan.get(), before}};
    const PreparedScan& scan = state.prepared(current);
    const IcpResult match = register_icp(backend_, *scan.cloud, before, models, icp_);
    ++tally.matches;
    tally.iterations += match.iterations();
    state.count_relaxation_match(current);
    if (!match.ok()) continue;  // keep the pose it had; a failed relaxation step moves nothing
    state.place(current, match.world_from_data, match);
    state.judged(current, registration_.judge(scan, match.world_from_data, before, models));
    const Pose change = rigid_inverse(before) * match.world_from_data;
    const bool moved = translation_norm(change) > settings_.moved_translation_cm ||
                       rotation_angle_deg(change) > settings_.moved_rotation_deg;
    if (!moved) continue;
    for (const std::size_t j : near) {
      if (j != 0 && !queued_[j]) {
        queue_.push_back(j);
        queued_[j] = true;
      }
    }
  }
  return tally;
}

}  // namespace minemap::detail
