// The CPU compute backend (cpu_backend.hpp).
#include "minemap/backend/cpu_backend.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <array>
#include <limits>
#include <stdexcept>

#include "minemap/filter/slice_filter_cpu.hpp"
#include "minemap/search/pairing_math.hpp"
#include "minemap/shared/minemap_shared.h"

namespace minemap {
namespace {

constexpr auto kQueriesPerBlock = static_cast<std::size_t>(kPairSumBlock);

class CpuPreparedCloud final : public PreparedCloud {
 public:
  CpuPreparedCloud(std::vector<Eigen::Vector3f> points, const KdTreeSettings& settings,
                   TreeBuild when = TreeBuild::kNow)
      : PreparedCloud(std::move(points), settings, when) {}
};

/// One model as the hot loop needs it: data->model and model->data transforms in float.
struct PlacedModel {
  const KdTree* tree;
  detail::RigidF model_from_data;
  detail::RigidF data_from_model;
  SkippedPoints skip;
};

std::vector<PlacedModel> place_models(std::span<const ModelPlacement> models, SearchMethod method) {
  require_exact_search_for_skips(models, method);
  std::vector<PlacedModel> placed;
  placed.reserve(models.size());
  for (const auto& m : models) {
    const Pose inverse = rigid_inverse(m.model_from_data);
    placed.push_back({&m.model->tree(),
                      {m.model_from_data.block<3, 3>(0, 0).cast<float>(), m.model_from_data.block<3, 1>(0, 3).cast<float>()},
                      {inverse.block<3, 3>(0, 0).cast<float>(), inverse.block<3, 1>(0, 3).cast<float>()},
                      m.skip});
  }
  return placed;
}

/// The closest point of data point `p` over all models. `hints` holds, per model, the tree point
/// found for the previous query of this block (or -1): queries run along the scan's slices, so that
/// point is usually a few cm away and its distance, rounded one ulp up, is a far tighter starting
/// bound than the pair distance. See detail::exact_nearest for why the result cannot change.
NearestPair find_nearest(const Eigen::Vector3f& p, const std::vector<PlacedModel>& models, SearchMethod method,
                         float max_squared_distance, std::int32_t* hints) {
  NearestPair result;
  float best = max_squared_distance;
  for (std::size_t k = 0; k < models.size(); ++k) {
    const PlacedModel& model = models[k];
    if (model.tree->empty()) continue;
    const Eigen::Vector3f q = model.model_from_data.apply(p);
    if (detail::squared_distance_to_bounds(*model.tree, q) >= best) continue;
    if (method == SearchMethod::kApproximate) {
      const auto& mean = model.tree->leaf_means()[static_cast<std::size_t>(detail::approximate_leaf(*model.tree, q))];
      const Eigen::Vector3f m(mean[0], mean[1], mean[2]);
      const float d = detail::squared_distance(mean[0], mean[1], mean[2], q);
      if (d < best) {
        best = d;
        result = {d, static_cast<std::int32_t>(k), -1, model.data_from_model.apply(m)};
      }
      continue;
    }
    std::int32_t hit = -1;
    if (method == SearchMethod::kExact) {
      detail::exact_nearest(*model.tree, q, best, hit, hints[k], model.skip);
      if (hit >= 0) hints[k] = hit;
    } else {
      detail::brute_force_nearest(*model.tree, q, best, hit);
    }
    if (hit >= 0) {
      const KdPoint& m = model.tree->points()[static_cast<std::size_t>(hit)];
      result = {best, static_cast<std::int32_t>(k), m.original_index,
                model.data_from_model.apply(Eigen::Vector3f(m.x, m.y, m.z))};
    }
  }
  return result;
}

/// Pairs every data point in blocks of kQueriesPerBlock (TBB over blocks, so any thread count
/// gives the same blocks) and hands each block's pairs, in index order, to `add(block, i, pair)`;
/// `block` starts as `empty`. Returns one Block per block, in block order, for the caller to add.
template <typename Block, typename Add>
std::vector<Block> pair_in_blocks(std::span<const Eigen::Vector3f> points, const std::vector<PlacedModel>& placed,
                                  SearchMethod method, float max_pair_dist_cm, const Block& empty, Add add) {
  const float max_squared = max_pair_dist_cm * max_pair_dist_cm;
  const std::size_t blocks = (points.size() + kQueriesPerBlock - 1) / kQueriesPerBlock;
  std::vector<Block> partial(blocks, empty);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks), [&](const tbb::blocked_range<std::size_t>& range) {
    // Hints never change a result (detail::exact_nearest), so they may carry across blocks.
    std::vector<std::int32_t> hints(placed.size(), -1);
    for (std::size_t b = range.begin(); b != range.end(); ++b) {
      const std::size_t end = std::min(points.size(), (b + 1) * kQueriesPerBlock);
      for (std::size_t i = b * kQueriesPerBlock; i < end; ++i) {
        add(partial[b], i, find_nearest(points[i], placed, method, max_squared, hints.data()));
      }
    }
  });
  return partial;
}

}  // namespace

std::shared_ptr<const PreparedCloud> CpuBackend::prepare(std::vector<Eigen::Vector3f> points_cm,
                                                         const KdTreeSettings& tree_settings, TreeBuild when) {
  return std::make_shared<CpuPreparedCloud>(std::move(points_cm), tree_settings, when);
}

std::vector<std::shared_ptr<const PreparedCloud>> CpuBackend::prepare_many(
    std::vector<std::vector<Eigen::Vector3f>> clouds_cm, const KdTreeSettings& tree_settings, TreeBuild when) {
  std::vector<std::shared_ptr<const PreparedCloud>> prepared(clouds_cm.size());
  // Building a tree touches nothing shared: one task per cloud, each tree the same as alone.
  tbb::parallel_for(std::size_t{0}, clouds_cm.size(), [&](std::size_t k) {
    prepared[k] = std::make_shared<CpuPreparedCloud>(std::move(clouds_cm[k]), tree_settings, when);
  });
  return prepared;
}

PairSums CpuBackend::pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                                  const PairingSettings& settings) {
  const auto points = data.points();
  const Eigen::Vector3d reference = data.centroid_cm();
  const float scale_squared = settings.robust_scale_cm * settings.robust_scale_cm;
  using Terms = std::array<double, kSumTerms>;  // one block's sums, as pair_sums_blocks makes them
  const std::vector<Terms> partial = pair_in_blocks(
      points, place_models(models, method), method, settings.max_pair_dist_cm, Terms{},
      [&](Terms& terms, std::size_t i, const NearestPair& pair) {
        if (pair.squared_distance_cm2 < 0.0f) return;
        const Eigen::Vector3f& p = points[i];
        const Eigen::Vector3f& m = pair.position_cm;
        const double pc[3] = {static_cast<double>(p.x()) - reference.x(), static_cast<double>(p.y()) - reference.y(),
                              static_cast<double>(p.z()) - reference.z()};
        const double mc[3] = {static_cast<double>(m.x()) - reference.x(), static_cast<double>(m.y()) - reference.y(),
                              static_cast<double>(m.z()) - reference.z()};
        shared::mm_add_point_to_point_terms(terms.data(), pc, mc, pair.squared_distance_cm2,
                                            shared::mm_robust_weight(pair.squared_distance_cm2, scale_squared));
      });
  PairSums total;
  total.reference_cm = reference;
  for (const Terms& terms : partial) total += PairSums::from_terms(terms.data(), reference);
  return total;
}

PlaneSums CpuBackend::pair_and_plane_sum(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                         SearchMethod method, const PairingSettings& settings,
                                         std::span<const Eigen::Vector3f> data_normals) {
  const auto points = data.points();
  if (data_normals.size() != points.size()) {
    throw std::invalid_argument("point-to-plane sums: one normal per data point expected");
  }
  PlaneSums total;
  total.reference_cm = data.centroid_cm();
  // One block's sums as plane_sums makes them, added as they are found.
  const std::vector<PlaneSums> partial =
      pair_in_blocks(points, place_models(models, method), method, settings.max_pair_dist_cm, total,
                     [&](PlaneSums& sums, std::size_t i, const NearestPair& pair) {
                       sums.add(points[i], data_normals[i], pair);
                     });
  for (const PlaneSums& sums : partial) total += sums;
  return total;
}

std::vector<NearestPair> CpuBackend::nearest(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                             SearchMethod method, const PairingSettings& settings) {
  const auto placed = place_models(models, method);
  const auto points = data.points();
  const float max_squared = settings.max_pair_dist_cm * settings.max_pair_dist_cm;
  std::vector<NearestPair> result(points.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), kQueriesPerBlock),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      std::vector<std::int32_t> hints(placed.size(), -1);
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        result[i] = find_nearest(points[i], placed, method, max_squared, hints.data());
                      }
                    });
  return result;
}

SliceFilterResult CpuBackend::filter_slices_checked(const Scan& scan, const SliceFilterSettings& settings) {
  return detail::filter_slices_cpu(scan, settings);
}

std::vector<std::vector<Eigen::Vector3f>> placed_within_on_host(std::span<const UnionPart> parts,
                                                                const Eigen::Vector3d& min_cm,
                                                                const Eigen::Vector3d& max_cm) {
  // One task per part, each its own list: the same lists for any thread count.
  std::vector<std::vector<Eigen::Vector3f>> placed(parts.size());
  tbb::parallel_for(std::size_t{0}, parts.size(), [&](std::size_t k) {
    // Eigen's product adds each row's terms in shared::mm_place_point's order (the kernel's; the
    // test MappingBackendsAgreeOnUnions holds both to it) and is vectorised: 10 % of a judging.
    const Eigen::Matrix3d rotation = parts[k].frame_from_cloud.block<3, 3>(0, 0);
    const Eigen::Vector3d translation = parts[k].frame_from_cloud.block<3, 1>(0, 3);
    for (const Eigen::Vector3f& p : parts[k].points_cm) {
      const Eigen::Vector3d q = rotation * p.cast<double>() + translation;
      if ((q.array() < min_cm.array()).any() || (q.array() > max_cm.array()).any()) continue;
      placed[k].push_back(q.cast<float>());
    }
  });
  return placed;
}

std::unique_ptr<ComputeBackend> make_cpu_backend() { return std::make_unique<CpuBackend>(); }

}  // namespace minemap
