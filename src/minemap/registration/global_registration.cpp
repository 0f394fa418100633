#include "minemap/registration/global_registration.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>
#if defined(__SSE2__)
#include <xmmintrin.h>
#endif

#include "minemap/registration/horn.hpp"
#include "minemap/search/pair_sums.hpp"

namespace minemap {
namespace {

using Pairs = std::vector<std::pair<std::uint32_t, std::uint32_t>>;

/// `to`'s features four at a time, bin by bin: block k holds features 4k..4k+3, bin b of feature
/// 4k+l at [k][b][l] (the last block padded with copies of the last feature, never chosen: a copy
/// is not closer than its original, which comes first).
using FeatureBlock = std::array<std::array<float, 4>, kFpfhBins>;

std::vector<FeatureBlock> interleaved(const std::vector<Fpfh>& to) {
  std::vector<FeatureBlock> blocks((to.size() + 3) / 4);
  for (std::size_t j = 0; j < blocks.size() * 4; ++j) {
    const Fpfh& f = to[std::min(j, to.size() - 1)];
    for (int b = 0; b < kFpfhBins; ++b) blocks[j / 4][b][j % 4] = f[b];
  }
  return blocks;
}

/// The index of `f`'s nearest feature in `to` (squared L2, summed bin by bin in order; the first
/// of equals), as a plain scan over `to` finds it. Four features are summed at once, lane by lane
/// in the same order, so each distance is the scan's to the last bit. A block is left after a third
/// or two thirds of the bins once all four partial sums reach the best so far: adding squares never
/// lowers a float sum, so none of the four could have been closer.
std::uint32_t nearest_feature(const Fpfh& f, const std::vector<FeatureBlock>& blocks, std::size_t count) {
  float best = std::numeric_limits<float>::infinity();
  std::uint32_t nearest = 0;
  for (std::size_t k = 0; k < blocks.size(); ++k) {
    const FeatureBlock& block = blocks[k];
    std::array<float, 4> sums{};
#if defined(__SSE2__)
    __m128 sum = _mm_setzero_ps();
    bool beyond = false;
    for (int b = 0; b < kFpfhBins; ++b) {
      const __m128 d = _mm_sub_ps(_mm_set1_ps(f[b]), _mm_loadu_ps(block[b].data()));
      sum = _mm_add_ps(sum, _mm_mul_ps(d, d));
      if ((b == 10 || b == 21) && _mm_movemask_ps(_mm_cmplt_ps(sum, _mm_set1_ps(best))) == 0) {
        beyond = true;
        break;
      }
    }
    if (beyond) continue;
    _mm_storeu_ps(sums.data(), sum);
#else
    for (int b = 0; b < kFpfhBins; ++b) {
      for (int l = 0; l < 4; ++l) {
        const float d = f[b] - block[b][l];
        sums[l] += d * d;
      }
    }
#endif
    for (int l = 0; l < 4; ++l) {
      const std::size_t j = 4 * k + std::size_t(l);
      if (j < count && sums[l] < best) {
        best = sums[l];
        nearest = static_cast<std::uint32_t>(j);
      }
    }
  }
  return nearest;
}

/// For each feature `from[which[k]]`, the index of its nearest feature in `to` (squared L2; the
/// first of equals). Brute force: a recovery's clouds hold thousands of features, not millions.
std::vector<std::uint32_t> nearest_features(const std::vector<Fpfh>& from, std::span<const std::uint32_t> which,
                                            const std::vector<Fpfh>& to) {
  std::vector<std::uint32_t> nearest(which.size(), 0);
  if (to.empty()) return nearest;
  const std::vector<FeatureBlock> blocks = interleaved(to);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, which.size(), 16), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t k = r.begin(); k < r.end(); ++k) nearest[k] = nearest_feature(from[which[k]], blocks, to.size());
  });
  return nearest;
}

/// Horn's transform of the pairs `which` (indices into `pairs`), data onto model.
std::optional<Pose> fit(const FeatureCloud& data, const FeatureCloud& model, const Pairs& pairs,
                        std::span<const std::uint32_t> which) {
  PairSums sums;
  for (const std::uint32_t k : which) {
    const Eigen::Vector3d p = data.points_cm[pairs[k].first].cast<double>();
    const Eigen::Vector3d m = model.points_cm[pairs[k].second].cast<double>();
    sums.count += 1.0;
    sums.weight += 1.0;
    sums.sum_data += p;
    sums.sum_model += m;
    sums.sum_data_model += p * m.transpose();
    sums.sum_squared_distance_cm2 += (p - m).squaredNorm();
  }
  return horn_transform(sums);
}

/// The pairs that agree with `pose` (within `distance_cm`), ascending.
std::vector<std::uint32_t> inliers_of(const FeatureCloud& data, const FeatureCloud& model, const Pairs& pairs,
                                      const Pose& pose, float distance_cm) {
  const Eigen::Matrix3f rotation = pose.block<3, 3>(0, 0).cast<float>();
  const Eigen::Vector3f translation = pose.block<3, 1>(0, 3).cast<float>();
  const float d2 = distance_cm * distance_cm;
  std::vector<std::uint32_t> inliers;
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    const Eigen::Vector3f moved = rotation * data.points_cm[pairs[k].first] + translation;
    if ((moved - model.points_cm[pairs[k].second]).squaredNorm() <= d2) inliers.push_back(std::uint32_t(k));
  }
  return inliers;
}

std::size_t count_inliers(const FeatureCloud& data, const FeatureCloud& model, const Pairs& pairs, const Pose& pose,
                          float distance_cm) {
  const Eigen::Matrix3f rotation = pose.block<3, 3>(0, 0).cast<float>();
  const Eigen::Vector3f translation = pose.block<3, 1>(0, 3).cast<float>();
  const float d2 = distance_cm * distance_cm;
  std::size_t count = 0;
  for (const auto& [d, m] : pairs) {
    count += (rotation * data.points_cm[d] + translation - model.points_cm[m]).squaredNorm() <= d2;
  }
  return count;
}

/// RMS distance the `probe` points move between pose a and pose b.
double rms_apart_cm(const Pose& a, const Pose& b, std::span<const Eigen::Vector3f> probe) {
  if (probe.empty()) return 0.0;
  double sum = 0.0;
  for (const Eigen::Vector3f& p : probe) {
    const Eigen::Vector4d h(p.x(), p.y(), p.z(), 1.0);
    sum += ((a * h) - (b * h)).head<3>().squaredNorm();
  }
  return std::sqrt(sum / double(probe.size()));
}

}  // namespace

void GlobalRegistrationSettings::validate() const {
  features.validate();
  if (!(inlier_distance_voxels > 0.0f)) {
    throw std::invalid_argument("global registration: inlier_distance_voxels must be > 0");
  }
  if (!(edge_similarity > 0.0 && edge_similarity <= 1.0)) {
    throw std::invalid_argument("global registration: edge_similarity must lie in (0, 1]");
  }
  if (max_iterations < 1 || min_iterations < 0 || min_iterations > max_iterations) {
    throw std::invalid_argument("global registration: need 0 <= min_iterations <= max_iterations, max >= 1");
  }
  if (!(confidence > 0.0 && confidence < 1.0)) throw std::invalid_argument("global registration: confidence must lie in (0, 1)");
  if (max_data_features < 0) throw std::invalid_argument("global registration: max_data_features must be >= 0");
  if (min_inliers < 3) throw std::invalid_argument("global registration: min_inliers must be >= 3");
  if (!(min_uniqueness >= 1.0)) throw std::invalid_argument("global registration: min_uniqueness must be >= 1");
  if (!(distinct_voxels > 0.0f)) throw std::invalid_argument("global registration: distinct_voxels must be > 0");
}

Pairs feature_pairs(const FeatureCloud& data, const FeatureCloud& model, std::size_t min_mutual,
                    std::size_t max_data_features) {
  // Evenly spaced data features (all of them when few), each with its nearest model feature...
  std::vector<std::uint32_t> sampled;
  const std::size_t stride = max_data_features > 0 ? (data.size() + max_data_features - 1) / max_data_features : 1;
  for (std::size_t i = 0; i < data.size(); i += std::max<std::size_t>(stride, 1)) sampled.push_back(std::uint32_t(i));
  const std::vector<std::uint32_t> forward = nearest_features(data.features, sampled, model.features);
  // ...and each model feature so chosen with its nearest among all the data's.
  std::vector<std::uint32_t> targets(forward.begin(), forward.end());
  std::sort(targets.begin(), targets.end());
  targets.erase(std::unique(targets.begin(), targets.end()), targets.end());
  const std::vector<std::uint32_t> backward = nearest_features(model.features, targets, data.features);
  Pairs all, mutual;
  for (std::size_t k = 0; k < sampled.size(); ++k) {
    all.emplace_back(sampled[k], forward[k]);
    const std::size_t t = std::lower_bound(targets.begin(), targets.end(), forward[k]) - targets.begin();
    if (backward[t] == sampled[k]) mutual.emplace_back(sampled[k], forward[k]);
  }
  return mutual.size() >= min_mutual ? mutual : all;
}

GlobalRegistrationResult register_globally(const FeatureCloud& data, const FeatureCloud& model,
                                           const GlobalRegistrationSettings& settings) {
  settings.validate();
  GlobalRegistrationResult result;
  result.data_features = data.size();
  result.model_features = model.size();
  char text[240];
  if (data.size() < 3 || model.size() < 3) {
    std::snprintf(text, sizeof text, "too few features (%zu in the scan, %zu in the map)", data.size(), model.size());
    result.why_not = text;
    return result;
  }
  const Pairs pairs = feature_pairs(data, model, 3 * std::size_t(settings.min_inliers), settings.max_data_features);
  result.correspondences = pairs.size();

  // Where the data is: every 64th-or-so feature point, to tell hypotheses apart by how far they move it.
  std::vector<Eigen::Vector3f> probe;
  const std::size_t stride = std::max<std::size_t>(1, data.size() / 64);
  for (std::size_t k = 0; k < data.size(); k += stride) probe.push_back(data.points_cm[k]);

  std::mt19937_64 random(settings.seed);
  const auto pick = [&](std::size_t n) { return static_cast<std::uint32_t>(random() % n); };
  const auto edge_agrees = [&](std::uint32_t a, std::uint32_t b) {
    const float in_data = (data.points_cm[pairs[a].first] - data.points_cm[pairs[b].first]).norm();
    const float in_model = (model.points_cm[pairs[a].second] - model.points_cm[pairs[b].second]).norm();
    // Points closer than a cube pin no rotation between them.
    if (in_data < settings.features.voxel_cm || in_model < settings.features.voxel_cm) return false;
    return std::min(in_data, in_model) >= settings.edge_similarity * std::max(in_data, in_model);
  };
  struct Hypothesis {
    std::size_t inliers;
    Pose pose;
  };
  std::vector<Hypothesis> kept;  // every hypothesis with half the inliers needed, for the rival
  std::size_t best = 0;
  long long needed = settings.max_iterations;
  int iteration = 0;
  for (; iteration < settings.max_iterations && (iteration < settings.min_iterations || iteration < needed);
       ++iteration) {
    const std::uint32_t sample[3] = {pick(pairs.size()), pick(pairs.size()), pick(pairs.size())};
    if (sample[0] == sample[1] || sample[0] == sample[2] || sample[1] == sample[2]) continue;
    if (!edge_agrees(sample[0], sample[1]) || !edge_agrees(sample[0], sample[2]) || !edge_agrees(sample[1], sample[2])) {
      continue;
    }
    const std::optional<Pose> pose = fit(data, model, pairs, sample);
    if (!pose) continue;
    const std::size_t inliers = count_inliers(data, model, pairs, *pose, settings.inlier_distance_cm());
    if (2 * inliers >= std::size_t(settings.min_inliers)) kept.push_back({inliers, *pose});
    if (inliers > best) {
      best = inliers;
      const double share = double(inliers) / double(pairs.size());
      const double miss = 1.0 - share * share * share;
      needed = miss <= 0.0 ? 0
                           : static_cast<long long>(std::ceil(std::log(1.0 - settings.confidence) / std::log(miss)));
    }
  }
  result.iterations = iteration;
  if (kept.empty()) {
    std::snprintf(text, sizeof text, "no hypothesis of %zu feature pairs held %d of them within %g cm", pairs.size(),
                  settings.min_inliers, double(settings.inlier_distance_cm()));
    result.why_not = text;
    return result;
  }
  // The best (the first of equals), refined on its inliers until they settle.
  const auto most = std::max_element(kept.begin(), kept.end(),
                                     [](const Hypothesis& a, const Hypothesis& b) { return a.inliers < b.inliers; });
  Pose pose = most->pose;
  std::vector<std::uint32_t> inliers = inliers_of(data, model, pairs, pose, settings.inlier_distance_cm());
  for (int round = 0; round < 5; ++round) {
    const std::optional<Pose> refined = fit(data, model, pairs, inliers);
    if (!refined) break;
    std::vector<std::uint32_t> again = inliers_of(data, model, pairs, *refined, settings.inlier_distance_cm());
    if (again.size() < inliers.size()) break;
    const bool settled = again == inliers;
    pose = *refined;
    inliers = std::move(again);
    if (settled) break;
  }
  result.model_from_data = pose;
  result.inliers = inliers.size();
  for (const Hypothesis& h : kept) {
    if (h.inliers > result.rival_inliers && rms_apart_cm(h.pose, pose, probe) > settings.distinct_cm()) {
      result.rival_inliers = h.inliers;
    }
  }
  if (result.inliers < std::size_t(settings.min_inliers)) {
    std::snprintf(text, sizeof text, "the best pose held %zu of %zu feature pairs within %g cm (fewer than %d)",
                  result.inliers, pairs.size(), double(settings.inlier_distance_cm()), settings.min_inliers);
    result.why_not = text;
  } else if (double(result.inliers) < settings.min_uniqueness * double(result.rival_inliers)) {
    std::snprintf(text, sizeof text,
                  "ambiguous: the best pose held %zu feature pairs, another more than %g cm from it %zu (less than "
                  "%.1f times as many): a self-similar place",
                  result.inliers, double(settings.distinct_cm()), result.rival_inliers, settings.min_uniqueness);
    result.why_not = text;
  } else {
    result.found = true;
  }
  return result;
}

}  // namespace minemap
