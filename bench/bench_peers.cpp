// Peers side by side on the same real pair with the same settings: all points of
// ../shared/data/fast_gicp_pair, point-to-point ICP, exact closest points within 25 cm, started at
// relative.txt, iterated until a step moves < 1e-5 cm and 1e-6 deg (Open3D: relative fitness and
// RMSE change < 1e-12), on this machine's cores.
//   BM_Peers/minemap_cpu      minemap's ICP (CPU backend, TBB)
//   BM_Peers/nanoflann_tbb    the same loop with nanoflann 1.4.2 + TBB as the closest-point search
//   BM_Peers/open3d           Open3D's RegistrationICP with TransformationEstimationPointToPoint
// Counters: icp_iterations, and the final pose's distance to minemap's (cm, deg). Built only when
// Debian's libopen3d-dev is installed (scripts/install-deps.sh bench).
#include <benchmark/benchmark.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <nanoflann.hpp>
#include <open3d/Open3D.h>
#ifdef MINEMAP_HAVE_PCL
#include <pcl/point_types.h>
#include <pcl/registration/icp.h>
#endif

#include "bench_common.hpp"
#include "nanoflann_cloud.hpp"
#include "minemap/registration/horn.hpp"
#include "minemap/registration/icp.hpp"

namespace minemap::bench {
namespace {

constexpr float kMaxPairDistCm = 25.0f;

Pose reference_start() {
  std::ifstream file(shared_data() / "fast_gicp_pair" / "relative.txt");
  Pose reference;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) file >> reference(r, c);
  reference.block<3, 1>(0, 3) *= 100.0;
  return orthonormalised(reference);
}

IcpSettings tight_settings() {
  IcpSettings settings;
  settings.method = SearchMethod::kExact;
  settings.max_pair_dist_cm = kMaxPairDistCm;
  settings.termination.min_translation_step_cm = 1e-5;
  settings.termination.min_rotation_step_deg = 1e-6;
  settings.termination.max_iterations = 500;
  return settings;
}

/// minemap's answer (T_target_source), the yardstick for the peers' poses.
const Pose& minemap_pose() {
  static const Pose pose = [] {
    const auto& pair = fast_gicp_pair();
    auto backend = make_cpu_backend();
    auto target = backend->prepare(pair.target.points_cm, {});
    auto source = backend->prepare(pair.source.points_cm, {});
    const WorldModel model{target.get(), Pose::Identity()};
    return register_icp(*backend, *source, reference_start(), {&model, 1}, tight_settings()).world_from_data;
  }();
  return pose;
}

/// The agreement rule: every peer lands within 1 mm of the others, so within 1 mm of minemap.
constexpr double kAgreeCm = 0.1;
constexpr double kAgreeDeg = 0.01;

void record(benchmark::State& state, const Pose& pose, int iterations) {
  const Pose difference = rigid_inverse(minemap_pose()) * pose;
  state.counters["icp_iterations"] = iterations;
  state.counters["to_minemap_cm"] = translation_norm(difference);
  state.counters["to_minemap_deg"] = rotation_angle_deg(difference);
  // A disagreement is an error in the JSON (error_occurred), which bench/run_benchmarks.sh reports
  // and fails on: a peer comparison with different answers would compare different work.
  if (translation_norm(difference) > kAgreeCm || rotation_angle_deg(difference) > kAgreeDeg) {
    state.SkipWithError(("final pose " + std::to_string(translation_norm(difference)) + " cm / " +
                         std::to_string(rotation_angle_deg(difference)) + " deg from minemap's (limit 1 mm)")
                            .c_str());
  }
}

void BM_Peers_minemap_cpu(benchmark::State& state) {
  const auto& pair = fast_gicp_pair();
  IcpResult result;
  for (auto _ : state) {
    auto backend = make_cpu_backend();
    auto target = backend->prepare(pair.target.points_cm, {});
    auto source = backend->prepare(pair.source.points_cm, {});
    const WorldModel model{target.get(), Pose::Identity()};
    result = register_icp(*backend, *source, reference_start(), {&model, 1}, tight_settings());
  }
  record(state, result.world_from_data, result.iterations());
}
BENCHMARK(BM_Peers_minemap_cpu)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

void BM_Peers_nanoflann_tbb(benchmark::State& state) {
  const auto& pair = fast_gicp_pair();
  const IcpSettings settings = tight_settings();
  Pose pose;
  int iterations = 0;
  for (auto _ : state) {
    NanoflannCloud adaptor{&pair.target.points_cm};
    NanoflannTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
    tree.buildIndex();
    pose = reference_start();
    iterations = 0;
    const auto& source = pair.source.points_cm;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const auto& p : source) centroid += p.cast<double>();
    centroid /= static_cast<double>(source.size());
    while (iterations < settings.termination.max_iterations) {
      const Eigen::Matrix3f r = pose.block<3, 3>(0, 0).cast<float>();
      const Eigen::Vector3f t = pose.block<3, 1>(0, 3).cast<float>();
      // Sums in the source frame, centred like minemap's, reduced deterministically.
      PairSums sums = tbb::parallel_deterministic_reduce(
          tbb::blocked_range<std::size_t>(0, source.size(), 1024), PairSums{},
          [&](const tbb::blocked_range<std::size_t>& range, PairSums partial) {
            for (std::size_t i = range.begin(); i != range.end(); ++i) {
              const Eigen::Vector3f q = r * source[i] + t;
              std::size_t index = 0;
              float distance = 0.0f;
              nanoflann::KNNResultSet<float> result(1);
              result.init(&index, &distance);
              tree.findNeighbors(result, q.data(), nanoflann::SearchParams());
              if (!(distance < kMaxPairDistCm * kMaxPairDistCm)) continue;
              const Eigen::Vector3f m_target = pair.target.points_cm[index];
              const Eigen::Vector3d m = (r.transpose() * (m_target - t)).cast<double>() - centroid;
              const Eigen::Vector3d p = source[i].cast<double>() - centroid;
              partial.count += 1.0;
              partial.sum_data += p;
              partial.sum_model += m;
              partial.sum_data_model += p * m.transpose();
              partial.sum_squared_distance_cm2 += distance;
            }
            return partial;
          },
          [](PairSums a, const PairSums& b) { return a += b; });
      sums.reference_cm = centroid;
      const auto step = horn_transform(sums);
      if (!step) break;
      pose = pose * *step;
      ++iterations;
      if (translation_norm(*step) < settings.termination.min_translation_step_cm &&
          rotation_angle_deg(*step) < settings.termination.min_rotation_step_deg) {
        break;
      }
    }
  }
  record(state, pose, iterations);
}
BENCHMARK(BM_Peers_nanoflann_tbb)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

void BM_Peers_open3d(benchmark::State& state) {
  const auto& pair = fast_gicp_pair();
  open3d::geometry::PointCloud target, source;
  for (const auto& p : pair.target.points_cm) target.points_.push_back(p.cast<double>());
  for (const auto& p : pair.source.points_cm) source.points_.push_back(p.cast<double>());
  open3d::pipelines::registration::RegistrationResult result;
  for (auto _ : state) {
    result = open3d::pipelines::registration::RegistrationICP(
        source, target, kMaxPairDistCm, reference_start(),
        open3d::pipelines::registration::TransformationEstimationPointToPoint(false),
        open3d::pipelines::registration::ICPConvergenceCriteria(1e-12, 1e-12, 500));
  }
  // Open3D does not report its iteration count; its fitness and RMSE are in the counters.
  record(state, result.transformation_, -1);
  state.counters["fitness"] = result.fitness_;
  state.counters["rmse_cm"] = result.inlier_rmse_;
}
BENCHMARK(BM_Peers_open3d)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

#ifdef MINEMAP_HAVE_PCL
void BM_Peers_pcl(benchmark::State& state) {
  const auto& pair = fast_gicp_pair();
  pcl::PointCloud<pcl::PointXYZ>::Ptr target(new pcl::PointCloud<pcl::PointXYZ>);
  pcl::PointCloud<pcl::PointXYZ>::Ptr source(new pcl::PointCloud<pcl::PointXYZ>);
  for (const auto& p : pair.target.points_cm) target->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  for (const auto& p : pair.source.points_cm) source->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  Eigen::Matrix4f final_transform = Eigen::Matrix4f::Identity();
  for (auto _ : state) {
    pcl::IterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> icp;
    icp.setInputSource(source);
    icp.setInputTarget(target);
    icp.setMaxCorrespondenceDistance(kMaxPairDistCm);
    icp.setMaximumIterations(500);
    icp.setTransformationEpsilon(1e-14);
    icp.setEuclideanFitnessEpsilon(1e-14);
    pcl::PointCloud<pcl::PointXYZ> aligned;
    icp.align(aligned, reference_start().cast<float>());
    final_transform = icp.getFinalTransformation();
  }
  // PCL does not report its iteration count.
  record(state, orthonormalised(final_transform.cast<double>()), -1);
}
BENCHMARK(BM_Peers_pcl)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);
#endif

}  // namespace
}  // namespace minemap::bench

BENCHMARK_MAIN();
