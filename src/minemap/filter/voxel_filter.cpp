#include "minemap/filter/voxel_filter.hpp"

#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <unordered_map>

namespace minemap {
namespace {

using Cell = std::array<std::int64_t, 3>;

struct CellHash {
  std::size_t operator()(const Cell& c) const noexcept {
    // The usual spatial-hash primes (Teschner et al. 2003).
    return static_cast<std::size_t>(static_cast<std::uint64_t>(c[0]) * 73856093u ^
                                    static_cast<std::uint64_t>(c[1]) * 19349663u ^
                                    static_cast<std::uint64_t>(c[2]) * 83492791u);
  }
};

}  // namespace

std::vector<Eigen::Vector3f> voxel_mean_filter(std::span<const Eigen::Vector3f> points_cm, float voxel_cm) {
  if (!(voxel_cm > 0.0f) || !std::isfinite(voxel_cm)) throw std::invalid_argument("voxel size must be a finite length > 0 cm");
  std::unordered_map<Cell, std::uint32_t, CellHash> cell_of;
  cell_of.reserve(points_cm.size() / 4 + 16);
  std::vector<Eigen::Vector3d> sums;
  std::vector<std::uint32_t> counts;
  const double inverse = 1.0 / static_cast<double>(voxel_cm);
  for (const Eigen::Vector3f& p : points_cm) {
    const Cell cell{static_cast<std::int64_t>(std::floor(static_cast<double>(p.x()) * inverse)),
                    static_cast<std::int64_t>(std::floor(static_cast<double>(p.y()) * inverse)),
                    static_cast<std::int64_t>(std::floor(static_cast<double>(p.z()) * inverse))};
    const auto [it, fresh] = cell_of.emplace(cell, static_cast<std::uint32_t>(sums.size()));
    if (fresh) {
      sums.push_back(Eigen::Vector3d::Zero());
      counts.push_back(0);
    }
    sums[it->second] += p.cast<double>();
    ++counts[it->second];
  }
  std::vector<Eigen::Vector3f> out(sums.size());
  for (std::size_t i = 0; i < sums.size(); ++i) out[i] = (sums[i] / static_cast<double>(counts[i])).cast<float>();
  return out;
}

}  // namespace minemap
