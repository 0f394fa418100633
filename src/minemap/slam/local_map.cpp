#include "minemap/slam/local_map.hpp"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <unordered_map>

namespace minemap::detail {
namespace {

/// A cell's key: its three integer coordinates, 21 bits each (+-10 km at 1 cm cells, in the
/// metascan's frame near the scan).
std::uint64_t cell_key(const Eigen::Vector3f& p, double scale) {
  const auto bits = [&](float v) {
    return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(double(v) * scale)) & 0x1FFFFF);
  };
  return bits(p.x()) | bits(p.y()) << 21 | bits(p.z()) << 42;
}

/// Which cells are taken: open addressing over a power-of-two table at most half full, so that
/// thinning a metascan of a million points costs milliseconds (a node-based set costs tens).
class CellSet {
 public:
  explicit CellSet(std::size_t most) {
    std::size_t size = 16;
    while (size < 2 * most) size *= 2;
    slots_.assign(size, kEmpty);
  }
  /// true when the cell was not taken before.
  bool insert(std::uint64_t key) {
    const std::size_t mask = slots_.size() - 1;
    for (std::size_t at = (key * 0x9E3779B97F4A7C15ull) >> 20 & mask;; at = (at + 1) & mask) {
      if (slots_[at] == key) return false;
      if (slots_[at] == kEmpty) {
        slots_[at] = key;
        return true;
      }
    }
  }

 private:
  static constexpr std::uint64_t kEmpty = ~std::uint64_t{0};  // no key has its top bit set
  std::vector<std::uint64_t> slots_;
};

}  // namespace

std::vector<Eigen::Vector3f> concatenated(const std::vector<std::vector<Eigen::Vector3f>>& parts) {
  std::size_t total = 0;
  for (const auto& part : parts) total += part.size();
  std::vector<Eigen::Vector3f> points;
  points.reserve(total);
  for (const auto& part : parts) points.insert(points.end(), part.begin(), part.end());
  return points;
}

std::vector<Eigen::Vector3f> first_point_per_cell(const std::vector<std::vector<Eigen::Vector3f>>& parts,
                                                  double cell_cm) {
  std::size_t total = 0;
  std::vector<std::size_t> offsets;  // where each part starts in the whole
  for (const auto& part : parts) {
    offsets.push_back(total);
    total += part.size();
  }
  const double scale = 1.0 / cell_cm;
  // The cells are dealt out to shards (one per thread) by their hash; each shard walks the points
  // in order and keeps the first point of each of its cells, so a point is kept exactly as one walk
  // in order would keep it, whatever the number of shards.
  const std::size_t shards = std::clamp<std::size_t>(tbb::this_task_arena::max_concurrency(), 1, 64);
  std::vector<std::uint64_t> keys(total);
  std::vector<std::uint8_t> shard_of(total);
  std::vector<std::vector<std::size_t>> counts(parts.size(), std::vector<std::size_t>(shards, 0));
  tbb::parallel_for(std::size_t{0}, parts.size(), [&](std::size_t k) {
    for (std::size_t j = 0; j < parts[k].size(); ++j) {
      const std::uint64_t key = cell_key(parts[k][j], scale);
      const auto shard = static_cast<std::uint8_t>(((key * 0xC2B2AE3D27D4EB4Full) >> 32) % shards);
      keys[offsets[k] + j] = key;
      shard_of[offsets[k] + j] = shard;
      ++counts[k][shard];
    }
  });
  std::vector<std::uint8_t> keep(total, 0);
  tbb::parallel_for(std::size_t{0}, shards, [&](std::size_t shard) {
    std::size_t mine = 0;
    for (const auto& count : counts) mine += count[shard];
    CellSet taken(mine);
    for (std::size_t p = 0; p < total; ++p) {
      if (shard_of[p] == shard && taken.insert(keys[p])) keep[p] = 1;
    }
  });
  std::vector<Eigen::Vector3f> points;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    for (std::size_t j = 0; j < parts[k].size(); ++j) {
      if (keep[offsets[k] + j]) points.push_back(parts[k][j]);
    }
  }
  return points;
}

std::vector<std::size_t> nearest_visits(const std::vector<std::size_t>& near, std::size_t i,
                                        const std::vector<std::size_t>& at_place, std::size_t gap, std::size_t most) {
  std::vector<std::size_t> sorted = at_place;
  sorted.push_back(i);
  std::sort(sorted.begin(), sorted.end());
  // The visits: runs of the scans at the place, each [first, last]; i's own is the one it falls in.
  std::vector<std::pair<std::size_t, std::size_t>> runs;
  std::size_t own = 0;
  for (const std::size_t j : sorted) {
    if (runs.empty() || j > runs.back().second + gap) runs.emplace_back(j, j);
    runs.back().second = j;
    if (j == i) own = runs.size() - 1;
  }
  if (most == 0 || runs.size() <= most) return near;
  const auto apart = [&](std::size_t r, std::size_t j) {
    return j < runs[r].first ? runs[r].first - j : j > runs[r].second ? j - runs[r].second : std::size_t{0};
  };
  std::vector<std::size_t> order(runs.size());
  for (std::size_t r = 0; r < runs.size(); ++r) order[r] = r;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    const auto rank = [&](std::size_t r) { return r == own ? 0 : r == 0 ? 1 : 2; };
    if (rank(a) != rank(b)) return rank(a) < rank(b);
    return apart(a, i) < apart(b, i);
  });
  std::vector<bool> keep(runs.size(), false);
  for (std::size_t k = 0; k < most; ++k) keep[order[k]] = true;
  std::vector<std::size_t> kept;
  for (const std::size_t j : near) {
    // j's visit: the run nearest it in the drive (the earlier of two alike).
    auto after = std::upper_bound(runs.begin(), runs.end(), j, [](std::size_t v, const auto& r) { return v < r.first; });
    std::size_t run = static_cast<std::size_t>(after - runs.begin());  // the first run after j
    if (run == runs.size() || (run > 0 && apart(run - 1, j) <= apart(run, j))) --run;
    if (keep[run]) kept.push_back(j);
  }
  return kept;
}

std::shared_ptr<const PreparedCloud> LocalMap::metascan(const SurveyState& state, std::size_t i, const Pose& standing,
                                                        const Pose& frame, const Pose& at, double grow_cm,
                                                        double thin_cm) const {
  std::vector<std::size_t> near = state.nearby(i, standing, i, double(settings_.icp.max_pair_dist_cm));
  if (settings_.loops.enabled) {  // recent scans only: a loop is the pose graph's to close
    const std::size_t gap = static_cast<std::size_t>(settings_.loops.min_scan_gap);
    std::erase_if(near, [&](std::size_t j) { return j + gap < i; });
  }
  return union_of(state, i, near, frame, at, grow_cm, thin_cm);
}

std::vector<std::size_t> LocalMap::judging_scans(const SurveyState& state, std::size_t i, const Pose& standing) const {
  std::vector<std::size_t> near = state.nearby(i, standing, state.size(), double(settings_.icp.max_pair_dist_cm));
  std::vector<std::size_t> at_place;  // the scans standing at i's place (a loop's candidate distance)
  for (const std::size_t j : near) {
    if ((state.pose(j).block<3, 1>(0, 3) - standing.block<3, 1>(0, 3)).norm() <= settings_.loops.max_distance_cm) {
      at_place.push_back(j);
    }
  }
  near = nearest_visits(near, i, at_place, static_cast<std::size_t>(settings_.loops.min_scan_gap),
                        static_cast<std::size_t>(settings_.loops.judge_max_visits));
  const std::size_t most = static_cast<std::size_t>(settings_.loops.judge_max_scans);
  if (most > 0 && near.size() > most) near.resize(most);  // the nearest (nearby sorts them)
  return near;
}

std::shared_ptr<const PreparedCloud> LocalMap::union_of(const SurveyState& state, std::size_t i,
                                                        const std::vector<std::size_t>& near, const Pose& frame,
                                                        const Pose& at, double grow_cm, double thin_cm) const {
  const Pose frame_inverse = rigid_inverse(frame);
  const PreparedCloud& own = *state.prepared(i).cloud;
  const std::array<Eigen::Vector3f, 2> corners = {own.bounds_min(), own.bounds_max()};
  const Bounds3d reach = world_bounds(corners, frame_inverse * at);
  const Eigen::Vector3d reach_min = reach.min_cm.array() - grow_cm, reach_max = reach.max_cm.array() + grow_cm;
  // Each scan's model points where it stands, within reach, concatenated in the list's order.
  std::vector<ModelPoints> models;
  models.reserve(near.size());
  for (const std::size_t j : near) models.push_back(state.model_points(j));  // one let go of is read, not taken back
  std::vector<UnionPart> placed(near.size());
  for (std::size_t k = 0; k < near.size(); ++k) {
    placed[k] = {models[k].points(), models[k].cloud(), frame_inverse * state.pose(near[k])};
  }
  const std::vector<std::vector<Eigen::Vector3f>> parts = backend_.placed_within(placed, reach_min, reach_max);
  return backend_.prepare(thin_cm > 0.0 ? first_point_per_cell(parts, thin_cm) : concatenated(parts), settings_.tree);
}

std::shared_ptr<const PreparedCloud> LocalMap::whole_union(const SurveyState& state,
                                                           const std::vector<std::size_t>& scans, const Pose& frame,
                                                           std::vector<std::int32_t>* starts) const {
  const Pose frame_inverse = rigid_inverse(frame);
  std::vector<ModelPoints> models;
  models.reserve(scans.size());
  for (const std::size_t j : scans) models.push_back(state.model_points(j));
  std::vector<UnionPart> placed(scans.size());
  for (std::size_t k = 0; k < scans.size(); ++k) {
    placed[k] = {models[k].points(), models[k].cloud(), frame_inverse * state.pose(scans[k])};
  }
  const double everywhere = std::numeric_limits<double>::max();  // finite: kernels may assume finite math
  const Eigen::Vector3d lowest = Eigen::Vector3d::Constant(-everywhere), highest = Eigen::Vector3d::Constant(everywhere);
  const std::vector<std::vector<Eigen::Vector3f>> parts = backend_.placed_within(placed, lowest, highest);
  if (starts != nullptr) {
    starts->assign(1, 0);
    for (const auto& part : parts) starts->push_back(starts->back() + static_cast<std::int32_t>(part.size()));
  }
  return backend_.prepare(concatenated(parts), settings_.tree);
}

std::vector<WorldModel> JudgingClouds::models(const SurveyState& state, const std::vector<std::size_t>& near,
                                              std::size_t judged) {
  static_assert(kBlockScans <= 64, "a block's scans are bits of one word");
  std::unordered_map<std::size_t, std::uint64_t> in_block;  // block -> which of its scans are in near (bits)
  for (const std::size_t j : near) in_block[j / kBlockScans] |= std::uint64_t{1} << (j % kBlockScans);
  std::vector<WorldModel> models;
  std::unordered_map<std::size_t, bool> whole;  // block -> searched as one tree (else scan by scan)
  for (const std::size_t j : near) {
    const std::size_t b = j / kBlockScans;
    const auto [at, first_of_block] = whole.try_emplace(b, false);
    if (first_of_block && at_one_place(state, b)) {
      // The block's scans not in near (the judged scan, or a run at either end): one run, left out.
      const std::size_t size = block_size(state, b);
      const std::uint64_t all = size == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << size) - 1;
      const std::uint64_t out = all & ~in_block[b];
      const int first = out == 0 ? 0 : std::countr_zero(out);
      const int last = out == 0 ? -1 : 63 - std::countl_zero(out);
      at->second = std::popcount(out) == last - first + 1;
      if (at->second) {
        const Held& held = block(state, b, judged);
        const std::int32_t from = held.starts[std::size_t(first)], to = held.starts[std::size_t(last + 1)];
        const SkippedPoints skip{from, to - from};
        models.push_back({held.cloud.get(), state.pose(b * kBlockScans), skip});
      }
    }
    if (!at->second) models.push_back({scan(state, j, judged), state.pose(j)});
  }
  return models;
}

const PreparedCloud* JudgingClouds::scan(const SurveyState& state, std::size_t j, std::size_t judged) {
  auto [at, fresh] = scans_.try_emplace(j);
  if (fresh) {
    const ModelPoints model = state.model_points(j);  // a let-go scan's read from the spill
    const std::span<const Eigen::Vector3f> points = model.points();
    at->second.cloud = local_map_.backend_.prepare(std::vector<Eigen::Vector3f>(points.begin(), points.end()),
                                                   local_map_.settings_.tree);
  }
  at->second.last_used = judged;
  return at->second.cloud.get();
}

bool JudgingClouds::at_one_place(const SurveyState& state, std::size_t b) {
  auto [at, fresh] = one_place_.try_emplace(b, false);
  if (fresh) {
    double path_cm = 0.0;
    const std::size_t first = b * kBlockScans, size = block_size(state, b);
    for (std::size_t j = first + 1; j < first + size; ++j) {
      path_cm += (state.pose(j).block<3, 1>(0, 3) - state.pose(j - 1).block<3, 1>(0, 3)).norm();
    }
    const double scans = double(size);
    at->second = path_cm * double(kOnePlaceScans) <= local_map_.settings_.loops.max_distance_cm * scans;
  }
  return at->second;
}

const JudgingClouds::Held& JudgingClouds::block(const SurveyState& state, std::size_t b, std::size_t judged) {
  auto [at, fresh] = blocks_.try_emplace(b);
  if (fresh) {
    std::vector<std::size_t> scans(block_size(state, b));
    for (std::size_t k = 0; k < scans.size(); ++k) scans[k] = b * kBlockScans + k;
    at->second.cloud = local_map_.whole_union(state, scans, state.pose(scans.front()), &at->second.starts);
  }
  at->second.last_used = judged;
  return at->second;
}

std::size_t JudgingClouds::block_size(const SurveyState& state, std::size_t b) {
  return std::min(kBlockScans, state.size() - b * kBlockScans);
}

void JudgingClouds::forget_unused(std::size_t judged) {
  const auto unused = [&](const auto& entry) { return entry.second.last_used + kKeptFor < judged; };
  std::erase_if(scans_, unused);
  // A block is not used while the judged scans are its own (judged scans in a row): kept through.
  std::erase_if(blocks_, [&](const auto& entry) { return entry.second.last_used + kKeptFor + kBlockScans < judged; });
}

}  // namespace minemap::detail
