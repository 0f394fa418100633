#include "minemap/filter/voxel_filter.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace minemap {
namespace {

using Cell = std::array<std::int64_t, 3>;

std::uint64_t hash_of(const Cell& c) {
  // The usual spatial-hash primes (Teschner et al. 2003), then a multiplicative mix for the high bits.
  const std::uint64_t h = static_cast<std::uint64_t>(c[0]) * 73856093u ^ static_cast<std::uint64_t>(c[1]) * 19349663u ^
                          static_cast<std::uint64_t>(c[2]) * 83492791u;
  return h * 0x9E3779B97F4A7C15ull;
}

/// Cell -> index of first appearance, open addressing with linear probing: a slot holds an index
/// into `cells` (kEmpty when free). A scan's 10^5 points cost no allocation per cell.
class CellIndex {
 public:
  explicit CellIndex(std::size_t expected_cells) { rehash(std::bit_ceil(std::max<std::size_t>(64, 2 * expected_cells))); }

  /// The cell's index, and whether it was added now.
  std::pair<std::uint32_t, bool> find_or_add(const Cell& cell) {
    if (2 * (cells_.size() + 1) > slots_.size()) rehash(2 * slots_.size());
    std::size_t slot = hash_of(cell) >> shift_;
    while (true) {
      const std::uint32_t index = slots_[slot];
      if (index == kEmpty) {
        slots_[slot] = static_cast<std::uint32_t>(cells_.size());
        cells_.push_back(cell);
        return {slots_[slot], true};
      }
      if (cells_[index] == cell) return {index, false};
      slot = (slot + 1) & (slots_.size() - 1);
    }
  }

 private:
  static constexpr std::uint32_t kEmpty = 0xFFFFFFFFu;
  void rehash(std::size_t capacity) {
    slots_.assign(capacity, kEmpty);
    shift_ = 64 - std::countr_zero(capacity);
    for (std::uint32_t i = 0; i < cells_.size(); ++i) {
      std::size_t slot = hash_of(cells_[i]) >> shift_;
      while (slots_[slot] != kEmpty) slot = (slot + 1) & (capacity - 1);
      slots_[slot] = i;
    }
  }
  std::vector<std::uint32_t> slots_;
  std::vector<Cell> cells_;
  int shift_ = 0;
};

}  // namespace

std::vector<Eigen::Vector3f> voxel_mean_filter(std::span<const Eigen::Vector3f> points_cm, float voxel_cm) {
  if (!(voxel_cm > 0.0f) || !std::isfinite(voxel_cm)) throw std::invalid_argument("voxel size must be a finite length > 0 cm");
  CellIndex cell_of(points_cm.size() / 4);
  std::vector<Eigen::Vector3d> sums;
  std::vector<std::uint32_t> counts;
  const double inverse = 1.0 / static_cast<double>(voxel_cm);
  for (const Eigen::Vector3f& p : points_cm) {
    const Cell cell{static_cast<std::int64_t>(std::floor(static_cast<double>(p.x()) * inverse)),
                    static_cast<std::int64_t>(std::floor(static_cast<double>(p.y()) * inverse)),
                    static_cast<std::int64_t>(std::floor(static_cast<double>(p.z()) * inverse))};
    const auto [index, fresh] = cell_of.find_or_add(cell);
    if (fresh) {
      sums.push_back(Eigen::Vector3d::Zero());
      counts.push_back(0);
    }
    sums[index] += p.cast<double>();
    ++counts[index];
  }
  std::vector<Eigen::Vector3f> out(sums.size());
  for (std::size_t i = 0; i < sums.size(); ++i) out[i] = (sums[i] / static_cast<double>(counts[i])).cast<float>();
  return out;
}

}  // namespace minemap
