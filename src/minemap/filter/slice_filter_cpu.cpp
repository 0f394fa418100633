// CPU reference of the slice filter. Float arithmetic in exactly the order of
// kernels/slice_filter.cl (contraction is off in both; the shared steps come from
// minemap/shared/minemap_shared.h), so both backends give the same bits.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "minemap/filter/slice_filter.hpp"
#include "minemap/filter/slice_filter_cpu.hpp"

namespace minemap {
namespace {

float squared_range(const Eigen::Vector3f& p) { return shared::mm_squared_norm3(p.x(), p.y(), p.z()); }

float squared_distance(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return shared::mm_squared_distance3(a.x(), a.y(), a.z(), b.x(), b.y(), b.z());
}

/// Index of the lower-median-range point in the window around `i` (ties broken by index).
int median_index(std::span<const Eigen::Vector3f> slice, int i, int half_window) {
  std::array<float, kMaxMedianWindow> keys{};
  std::array<int, kMaxMedianWindow> ids{};
  const int first = std::max(0, i - half_window);
  const int last = std::min(static_cast<int>(slice.size()) - 1, i + half_window);
  int n = 0;
  for (int j = first; j <= last; ++j) {
    shared::mm_insert_sorted(keys.data(), ids.data(), n, squared_range(slice[static_cast<std::size_t>(j)]), j);
    ++n;
  }
  return ids[(n - 1) / 2];
}

/// Output of one slice: points with their weights (how many inputs each mean stands for).
struct SliceOutput {
  std::vector<Eigen::Vector3f> points;
  std::vector<float> weights;
  std::size_t replaced = 0;

  void emit(Eigen::Vector3f mean, float weight, float min_spacing_sq) {
    while (!points.empty() && squared_distance(mean, points.back()) < min_spacing_sq) {
      const Eigen::Vector3f& last = points.back();
      const float last_weight = weights.back();
      const float total = weight + last_weight;
      mean = Eigen::Vector3f((mean.x() * weight + last.x() * last_weight) / total,
                             (mean.y() * weight + last.y() * last_weight) / total,
                             (mean.z() * weight + last.z() * last_weight) / total);
      weight = total;
      points.pop_back();
      weights.pop_back();
    }
    points.push_back(mean);
    weights.push_back(weight);
  }
};

SliceOutput filter_slice(std::span<const Eigen::Vector3f> slice, const SliceFilterSettings& settings) {
  SliceOutput out;
  const int half_window = settings.median_window / 2;
  const float min_spacing_sq = settings.min_point_spacing_cm * settings.min_point_spacing_cm;
  Eigen::Vector3f cluster_sum = Eigen::Vector3f::Zero();
  Eigen::Vector3f anchor = Eigen::Vector3f::Zero();
  int cluster_size = 0;
  auto flush = [&] {
    const auto n = static_cast<float>(cluster_size);
    out.emit(Eigen::Vector3f(cluster_sum.x() / n, cluster_sum.y() / n, cluster_sum.z() / n), n, min_spacing_sq);
  };
  for (int i = 0; i < static_cast<int>(slice.size()); ++i) {
    Eigen::Vector3f p = slice[static_cast<std::size_t>(i)];
    if (settings.median_enabled) {
      const int m = median_index(slice, i, half_window);
      const float range = std::sqrt(squared_range(p));
      const float median_range = std::sqrt(squared_range(slice[static_cast<std::size_t>(m)]));
      if (std::fabs(range - median_range) > settings.outlier_threshold_cm) {
        p = slice[static_cast<std::size_t>(m)];
        ++out.replaced;
      }
    }
    if (!settings.reduction_enabled) {
      out.points.push_back(p);
      continue;
    }
    if (cluster_size == 0) {
      cluster_sum = p;
      anchor = p;
      cluster_size = 1;
    } else if (squared_distance(p, anchor) < min_spacing_sq) {
      cluster_sum = Eigen::Vector3f(cluster_sum.x() + p.x(), cluster_sum.y() + p.y(), cluster_sum.z() + p.z());
      cluster_size += 1;
    } else {
      flush();
      cluster_sum = p;
      anchor = p;
      cluster_size = 1;
    }
  }
  if (settings.reduction_enabled && cluster_size > 0) flush();
  return out;
}

}  // namespace

SliceFilterResult unfiltered_result(const Scan& scan, const std::string& backend) {
  SliceFilterResult result;
  result.backend = backend;
  result.points_in = scan.size();
  result.points_cm = scan.points_cm;
  result.points_in_kept_slices = scan.size();
  result.slice_offsets = {0, static_cast<std::uint32_t>(scan.size())};
  return result;
}

std::vector<std::size_t> kept_slice_indices(const Scan& scan, const SliceFilterSettings& settings) {
  std::vector<std::size_t> kept;
  for (std::size_t s = 0; s < scan.num_slices(); s += static_cast<std::size_t>(settings.slice_stride)) kept.push_back(s);
  return kept;
}

SliceFilterResult filter_scan_cpu(const Scan& scan, const SliceFilterSettings& settings) {
  settings.validate();
  return scan.has_slices() ? detail::filter_slices_cpu(scan, settings) : unfiltered_result(scan, "cpu");
}

SliceFilterResult detail::filter_slices_cpu(const Scan& scan, const SliceFilterSettings& settings) {
  SliceFilterResult result;
  result.backend = "cpu";
  result.points_in = scan.size();
  const std::vector<std::size_t> kept = kept_slice_indices(scan, settings);
  std::vector<SliceOutput> outputs(kept.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, kept.size()), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t k = range.begin(); k != range.end(); ++k) outputs[k] = filter_slice(scan.slice(kept[k]), settings);
  });
  result.slice_offsets.push_back(0);
  for (std::size_t k = 0; k < kept.size(); ++k) {
    result.points_in_kept_slices += scan.slice(kept[k]).size();
    result.outliers_replaced += outputs[k].replaced;
    result.points_cm.insert(result.points_cm.end(), outputs[k].points.begin(), outputs[k].points.end());
    result.slice_offsets.push_back(static_cast<std::uint32_t>(result.points_cm.size()));
  }
  return result;
}

std::vector<Eigen::Vector3f> thin_unstructured(const Scan& scan, int stride) {
  if (stride <= 1) return scan.points_cm;
  std::vector<Eigen::Vector3f> out;
  out.reserve(scan.size() / static_cast<std::size_t>(stride) + 1);
  for (std::size_t i = 0; i < scan.size(); i += static_cast<std::size_t>(stride)) out.push_back(scan.points_cm[i]);
  return out;
}

}  // namespace minemap
