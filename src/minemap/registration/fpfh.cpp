#include "minemap/registration/fpfh.hpp"

#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <unordered_map>

namespace minemap {
namespace {

constexpr int kBinsPerAngle = kFpfhBins / 3;

/// Integer cube coordinates, 21 bits each (+-10 km at 1 cm cubes): a key for a hash map.
std::uint64_t key_of(std::int64_t x, std::int64_t y, std::int64_t z) {
  constexpr std::int64_t mask = 0x1FFFFF;
  return std::uint64_t(x & mask) | std::uint64_t(y & mask) << 21 | std::uint64_t(z & mask) << 42;
}

Eigen::Array3i cube_of(const Eigen::Vector3f& p, float cube_cm) {
  return (p.array() / cube_cm).floor().cast<int>();
}

/// The points within a radius of a point, through cubes of the radius's size (27 looked at).
class NeighbourGrid {
 public:
  NeighbourGrid(std::span<const Eigen::Vector3f> points, float radius_cm) : points_(points), radius_cm_(radius_cm) {
    for (std::size_t k = 0; k < points.size(); ++k) {
      const Eigen::Array3i c = cube_of(points[k], radius_cm);
      cubes_[key_of(c.x(), c.y(), c.z())].push_back(static_cast<std::uint32_t>(k));
    }
  }
  /// Indices within the radius of point k (itself included), ascending.
  void within(std::size_t k, std::vector<std::uint32_t>& out) const {
    out.clear();
    const Eigen::Vector3f& p = points_[k];
    const Eigen::Array3i c = cube_of(p, radius_cm_);
    const float r2 = radius_cm_ * radius_cm_;
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dz = -1; dz <= 1; ++dz) {
          const auto found = cubes_.find(key_of(c.x() + dx, c.y() + dy, c.z() + dz));
          if (found == cubes_.end()) continue;
          for (const std::uint32_t j : found->second) {
            if ((points_[j] - p).squaredNorm() <= r2) out.push_back(j);
          }
        }
      }
    }
    std::sort(out.begin(), out.end());  // the cubes' order is the hash map's: sorted, it is the points'
  }

 private:
  std::span<const Eigen::Vector3f> points_;
  float radius_cm_;
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> cubes_;
};

int bin_of(float value, float low, float high) {
  const int bin = static_cast<int>(std::floor(kBinsPerAngle * (value - low) / (high - low)));
  return std::clamp(bin, 0, kBinsPerAngle - 1);
}

}  // namespace

void FeatureSettings::validate() const {
  if (!(voxel_cm > 0.0f) || !std::isfinite(voxel_cm)) throw std::invalid_argument("features: voxel_cm must be > 0");
  if (!(normal_radius_voxels >= 1.0f) || !std::isfinite(normal_radius_voxels)) {
    throw std::invalid_argument("features: normal_radius_voxels must be >= 1");
  }
  if (!(feature_radius_voxels >= 1.0f) || !std::isfinite(feature_radius_voxels)) {
    throw std::invalid_argument("features: feature_radius_voxels must be >= 1");
  }
  if (min_normal_neighbours < 3) throw std::invalid_argument("features: min_normal_neighbours must be >= 3");
}

std::vector<Eigen::Vector3f> cube_means(std::span<const Eigen::Vector3f> points_cm, float voxel_cm) {
  std::unordered_map<std::uint64_t, std::uint32_t> index_of;
  std::vector<Eigen::Vector3d> sums;
  std::vector<std::uint32_t> counts;
  for (const Eigen::Vector3f& p : points_cm) {
    if (!p.allFinite()) continue;
    const Eigen::Array3i c = cube_of(p, voxel_cm);
    const auto [at, added] = index_of.try_emplace(key_of(c.x(), c.y(), c.z()), std::uint32_t(sums.size()));
    if (added) {
      sums.emplace_back(Eigen::Vector3d::Zero());
      counts.push_back(0);
    }
    sums[at->second] += p.cast<double>();
    ++counts[at->second];
  }
  std::vector<Eigen::Vector3f> means(sums.size());
  for (std::size_t k = 0; k < sums.size(); ++k) means[k] = (sums[k] / double(counts[k])).cast<float>();
  return means;
}

bool pair_angles(const Eigen::Vector3f& p, const Eigen::Vector3f& n_p, const Eigen::Vector3f& q,
                 const Eigen::Vector3f& n_q, std::array<float, 3>& angles) {
  Eigen::Vector3f line = q - p;
  const float length = line.norm();
  if (!(length > 0.0f)) return false;
  const float cos_p = n_p.dot(line) / length, cos_q = n_q.dot(line) / length;
  // The source is the point whose normal is closer to the line: the frame is then well defined.
  const bool swap = std::acos(std::min(1.0f, std::abs(cos_p))) > std::acos(std::min(1.0f, std::abs(cos_q)));
  const Eigen::Vector3f& u = swap ? n_q : n_p;
  const Eigen::Vector3f& target_normal = swap ? n_p : n_q;
  if (swap) line = -line;
  const float phi = swap ? -cos_q : cos_p;
  Eigen::Vector3f v = line.cross(u);
  const float v_norm = v.norm();
  if (!(v_norm > 0.0f)) return false;
  v /= v_norm;
  const Eigen::Vector3f w = u.cross(v);
  angles = {std::atan2(w.dot(target_normal), u.dot(target_normal)), v.dot(target_normal), phi};
  return true;
}

FeatureCloud describe_fpfh(std::span<const Eigen::Vector3f> points_cm, const Eigen::Vector3f& viewpoint_cm,
                           const FeatureSettings& settings) {
  settings.validate();
  const std::vector<Eigen::Vector3f> thinned = cube_means(points_cm, settings.voxel_cm);
  const std::size_t n = thinned.size();

  // Normals: the direction of least spread of the neighbours (PCA), toward the viewpoint.
  std::vector<Eigen::Vector3f> normals(n, Eigen::Vector3f::Zero());
  {
    const NeighbourGrid grid(thinned, settings.normal_radius_cm());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const tbb::blocked_range<std::size_t>& range) {
      std::vector<std::uint32_t> near;
      for (std::size_t k = range.begin(); k < range.end(); ++k) {
        grid.within(k, near);
        if (static_cast<int>(near.size()) < settings.min_normal_neighbours) continue;
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (const std::uint32_t j : near) mean += thinned[j].cast<double>();
        mean /= double(near.size());
        Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
        for (const std::uint32_t j : near) {
          const Eigen::Vector3d d = thinned[j].cast<double>() - mean;
          covariance += d * d.transpose();
        }
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
        if (solver.info() != Eigen::Success || !(solver.eigenvalues()(1) > 0.0)) continue;  // a line: no plane
        Eigen::Vector3f normal = solver.eigenvectors().col(0).cast<float>().normalized();
        if (normal.dot(viewpoint_cm - thinned[k]) < 0.0f) normal = -normal;
        normals[k] = normal;
      }
    });
  }
  FeatureCloud cloud;
  for (std::size_t k = 0; k < n; ++k) {
    if (normals[k].squaredNorm() > 0.0f) {
      cloud.points_cm.push_back(thinned[k]);
      cloud.normals.push_back(normals[k]);
    }
  }
  const std::size_t m = cloud.size();
  const NeighbourGrid grid(cloud.points_cm, settings.feature_radius_cm());
  std::vector<std::vector<std::uint32_t>> neighbours(m);
  std::vector<Fpfh> simple(m);  // SPFH: each point's own histogram over its neighbours
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, m, 256), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t k = range.begin(); k < range.end(); ++k) {
      grid.within(k, neighbours[k]);
      std::erase(neighbours[k], static_cast<std::uint32_t>(k));
      Fpfh& histogram = simple[k];
      histogram.fill(0.0f);
      std::array<int, kFpfhBins> counts{};
      int pairs = 0;
      for (const std::uint32_t j : neighbours[k]) {
        std::array<float, 3> angles;
        if (!pair_angles(cloud.points_cm[k], cloud.normals[k], cloud.points_cm[j], cloud.normals[j], angles)) continue;
        ++counts[bin_of(angles[0], -float(M_PI), float(M_PI))];
        ++counts[kBinsPerAngle + bin_of(angles[1], -1.0f, 1.0f)];
        ++counts[2 * kBinsPerAngle + bin_of(angles[2], -1.0f, 1.0f)];
        ++pairs;
      }
      if (pairs == 0) continue;
      for (int b = 0; b < kFpfhBins; ++b) histogram[b] = 100.0f * float(counts[b]) / float(pairs);
    }
  });
  cloud.features.resize(m);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, m, 256), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t k = range.begin(); k < range.end(); ++k) {
      std::array<double, kFpfhBins> weighted{};
      for (const std::uint32_t j : neighbours[k]) {  // ascending: a fixed order of the sums
        const double weight = 1.0 / double((cloud.points_cm[j] - cloud.points_cm[k]).squaredNorm());
        for (int b = 0; b < kFpfhBins; ++b) weighted[b] += weight * simple[j][b];
      }
      Fpfh& feature = cloud.features[k];
      for (int block = 0; block < 3; ++block) {
        double sum = 0.0;
        for (int b = 0; b < kBinsPerAngle; ++b) sum += weighted[block * kBinsPerAngle + b];
        const double scale = sum > 0.0 ? 100.0 / sum : 0.0;
        for (int b = 0; b < kBinsPerAngle; ++b) {
          const int at = block * kBinsPerAngle + b;
          feature[at] = simple[k][at] + float(weighted[at] * scale);
        }
      }
    }
  });
  return cloud;
}

}  // namespace minemap
