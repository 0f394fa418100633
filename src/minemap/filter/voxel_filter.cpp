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

/// The cell of a point: floor of each coordinate times `inverse` (1 / cell size).
template <typename Point>
Cell cell_of_point(const Point& p, double inverse) {
  return {static_cast<std::int64_t>(std::floor(static_cast<double>(p.x()) * inverse)),
          static_cast<std::int64_t>(std::floor(static_cast<double>(p.y()) * inverse)),
          static_cast<std::int64_t>(std::floor(static_cast<double>(p.z()) * inverse))};
}

/// The voxel means of `points_cm`, and of `values` when given.
std::vector<Eigen::Vector3f> voxel_means(std::span<const Eigen::Vector3f> points_cm, float voxel_cm,
                                         std::span<const float> values, std::vector<float>* value_means) {
  if (!(voxel_cm > 0.0f) || !std::isfinite(voxel_cm)) throw std::invalid_argument("voxel size must be a finite length > 0 cm");
  if (value_means != nullptr && values.size() != points_cm.size()) {
    throw std::invalid_argument("voxel_mean_filter: one value per point expected");
  }
  CellIndex cell_of(points_cm.size() / 4);
  std::vector<Eigen::Vector3d> sums;
  std::vector<double> value_sums;
  std::vector<std::uint32_t> counts;
  const double inverse = 1.0 / static_cast<double>(voxel_cm);
  for (std::size_t k = 0; k < points_cm.size(); ++k) {
    const Eigen::Vector3f& p = points_cm[k];
    const auto [index, fresh] = cell_of.find_or_add(cell_of_point(p, inverse));
    if (fresh) {
      sums.push_back(Eigen::Vector3d::Zero());
      counts.push_back(0);
      if (value_means != nullptr) value_sums.push_back(0.0);
    }
    sums[index] += p.cast<double>();
    ++counts[index];
    if (value_means != nullptr) value_sums[index] += static_cast<double>(values[k]);
  }
  std::vector<Eigen::Vector3f> out(sums.size());
  for (std::size_t i = 0; i < sums.size(); ++i) out[i] = (sums[i] / static_cast<double>(counts[i])).cast<float>();
  if (value_means != nullptr) {
    value_means->resize(sums.size());
    for (std::size_t i = 0; i < sums.size(); ++i) {
      (*value_means)[i] = static_cast<float>(value_sums[i] / static_cast<double>(counts[i]));
    }
  }
  return out;
}

}  // namespace

std::vector<Eigen::Vector3f> voxel_mean_filter(std::span<const Eigen::Vector3f> points_cm, float voxel_cm) {
  return voxel_means(points_cm, voxel_cm, {}, nullptr);
}

std::vector<Eigen::Vector3f> voxel_mean_filter(std::span<const Eigen::Vector3f> points_cm, float voxel_cm,
                                               std::span<const float> values, std::vector<float>& value_means) {
  return voxel_means(points_cm, voxel_cm, values, &value_means);
}

std::vector<std::size_t> voxel_first_points(std::span<const Eigen::Vector3d> points, double voxel) {
  if (!(voxel > 0.0) || !std::isfinite(voxel)) throw std::invalid_argument("voxel size must be a finite length > 0");
  CellIndex cell_of(points.size() / 4);
  std::vector<std::size_t> kept;
  const double inverse = 1.0 / voxel;
  for (std::size_t k = 0; k < points.size(); ++k) {
    if (cell_of.find_or_add(cell_of_point(points[k], inverse)).second) kept.push_back(k);
  }
  return kept;
}

}  // namespace minemap
