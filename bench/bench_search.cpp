// Closest-point search and slice-filter throughput (issues: filter speed, search speed, Fig. 5).
//   BM_SliceFilter/<backend>           points per second on a paper-size scan (361 x 341)
//   BM_NearestNeighbour/<impl>         exact 1-NN queries per second, 25 cm bound, fast_gicp_pair
//   BM_RegistrationBucketSize/<search>/<bucket>   Fig. 5: one pair registration against bucket size
// Run with --benchmark_format=json (bench/run_benchmarks.sh does, and writes the tables).
#include <benchmark/benchmark.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#ifdef MINEMAP_HAVE_NANOFLANN  // the nanoflann rows are built where CMake finds nanoflann
#include <nanoflann.hpp>

#include "nanoflann_cloud.hpp"
#endif
#ifdef MINEMAP_HAVE_PCL
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_types.h>
#endif

#include "bench_common.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/search/pairing.hpp"

namespace minemap::bench {
namespace {

void BM_SliceFilter(benchmark::State& state, Backend backend) {
  const Scan& scan = simulated_pair().model;
  SliceFilterSettings settings;
  auto filter = backend_or_skip(state, backend);
  if (!filter) return;
  auto warm = filter->filter_slices(scan, settings);  // fills caches
  for (auto _ : state) {
    auto result = filter->filter_slices(scan, settings);
    benchmark::DoNotOptimize(result.points_cm.data());
  }
  state.counters["points_in"] = static_cast<double>(scan.size());
  state.counters["points_out"] = static_cast<double>(warm.points_out());
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * scan.size()));
}
BENCHMARK_CAPTURE(BM_SliceFilter, cpu, Backend::kCpu)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_SliceFilter, opencl, Backend::kOpenCl)->Unit(benchmark::kMillisecond)->UseRealTime();

// ---- nearest neighbour: minemap backends against nanoflann + TBB on the same points and bound ----

#ifdef MINEMAP_HAVE_NANOFLANN
/// nanoflann result set for the closest point within a squared radius (the same bound as minemap).
class BoundedNearest {
 public:
  explicit BoundedNearest(float max_squared) : best_(max_squared) {}
  std::size_t size() const { return index_ < 0 ? 0 : 1; }
  bool full() const { return true; }
  bool addPoint(float distance, std::size_t index) {
    if (distance < best_) {
      best_ = distance;
      index_ = static_cast<long>(index);
    }
    return true;
  }
  float worstDist() const { return best_; }
  float best() const { return best_; }
  long index() const { return index_; }

 private:
  float best_;
  long index_ = -1;
};
#endif

constexpr float kMaxPairDistCm = 25.0f;

/// Model points and query points in the model's frame: "lidar" = fast_gicp_pair (source at
/// identity), "mine" = two simulated paper-size scans, the data scan placed by its true pose.
struct QueryInput {
  std::vector<Eigen::Vector3f> model, queries;
};
const QueryInput& query_input(const std::string& data) {
  static const QueryInput lidar{fast_gicp_pair().target.points_cm, fast_gicp_pair().source.points_cm};
  static const QueryInput mine = [] {
    const auto& pair = simulated_pair();
    QueryInput in{pair.model.points_cm, {}};
    const Pose model_from_data = rigid_inverse(pair.true_world_from_model) * pair.true_world_from_data;
    for (const auto& p : pair.data.points_cm) {
      in.queries.push_back((model_from_data.block<3, 3>(0, 0) * p.cast<double>() + model_from_data.block<3, 1>(0, 3)).cast<float>());
    }
    return in;
  }();
  return data == "mine" ? mine : lidar;
}

#ifdef MINEMAP_HAVE_NANOFLANN
void BM_NearestNeighbour_nanoflann_tbb(benchmark::State& state, std::string data) {
  const QueryInput& in = query_input(data);
  NanoflannCloud adaptor{&in.model};
  NanoflannTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  const auto& queries = in.queries;
  std::vector<float> best(queries.size());
  for (auto _ : state) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, queries.size(), 1024), [&](const auto& range) {
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
        BoundedNearest result(kMaxPairDistCm * kMaxPairDistCm);
        tree.findNeighbors(result, queries[i].data(), nanoflann::SearchParams());
        best[i] = result.best();
      }
    });
    benchmark::DoNotOptimize(best.data());
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * queries.size()));
}
BENCHMARK_CAPTURE(BM_NearestNeighbour_nanoflann_tbb, lidar, "lidar")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_NearestNeighbour_nanoflann_tbb, mine, "mine")->Unit(benchmark::kMillisecond)->UseRealTime();
#endif

#ifdef MINEMAP_HAVE_PCL
/// PCL's KdTreeFLANN, the same bound (radiusSearch with at most one neighbour), TBB over queries.
void BM_NearestNeighbour_pcl_kdtreeflann_tbb(benchmark::State& state, std::string data) {
  const QueryInput& in = query_input(data);
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  for (const auto& p : in.model) cloud->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(cloud);
  std::vector<float> best(in.queries.size());
  for (auto _ : state) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, in.queries.size(), 1024), [&](const auto& range) {
      std::vector<int> index;
      std::vector<float> distance;
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
        const auto& q = in.queries[i];
        best[i] = tree.radiusSearch(pcl::PointXYZ(q.x(), q.y(), q.z()), kMaxPairDistCm, index, distance, 1) > 0
                      ? distance[0]
                      : -1.0f;
      }
    });
    benchmark::DoNotOptimize(best.data());
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * in.queries.size()));
}
BENCHMARK_CAPTURE(BM_NearestNeighbour_pcl_kdtreeflann_tbb, lidar, "lidar")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_NearestNeighbour_pcl_kdtreeflann_tbb, mine, "mine")->Unit(benchmark::kMillisecond)->UseRealTime();
#endif

void BM_NearestNeighbour_minemap(benchmark::State& state, std::string input, Backend backend, SearchMethod method) {
  const QueryInput& in = query_input(input);
  auto pairing = backend_or_skip(state, backend);
  if (!pairing) return;
  auto model = pairing->prepare(in.model, {});
  auto data = pairing->prepare(in.queries, {});
  const ModelPlacement placement{model.get(), Pose::Identity()};
  pairing->pair_and_sum(*data, {&placement, 1}, method, {kMaxPairDistCm});  // warm-up
  for (auto _ : state) {
    auto sums = pairing->pair_and_sum(*data, {&placement, 1}, method, {kMaxPairDistCm});
    benchmark::DoNotOptimize(sums.count);
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * in.queries.size()));
}
BENCHMARK_CAPTURE(BM_NearestNeighbour_minemap, lidar/cpu_exact, "lidar", Backend::kCpu, SearchMethod::kExact)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_NearestNeighbour_minemap, lidar/cpu_approximate, "lidar", Backend::kCpu, SearchMethod::kApproximate)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_NearestNeighbour_minemap, lidar/opencl_exact, "lidar", Backend::kOpenCl, SearchMethod::kExact)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_NearestNeighbour_minemap, lidar/opencl_approximate, "lidar", Backend::kOpenCl, SearchMethod::kApproximate)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_NearestNeighbour_minemap, mine/cpu_exact, "mine", Backend::kCpu, SearchMethod::kExact)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_NearestNeighbour_minemap, mine/cpu_approximate, "mine", Backend::kCpu, SearchMethod::kApproximate)
    ->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_NearestNeighbour_minemap, mine/opencl_exact, "mine", Backend::kOpenCl, SearchMethod::kExact)
    ->Unit(benchmark::kMillisecond)->UseRealTime();

/// Queries alone (no ICP sums): minemap's closest points written per query, as the nanoflann and
/// PCL loops write theirs.
void BM_NearestNeighbour_minemap_queries_only(benchmark::State& state, std::string input) {
  const QueryInput& in = query_input(input);
  auto pairing = make_cpu_backend();
  auto model = pairing->prepare(in.model, {});
  auto data = pairing->prepare(in.queries, {});
  const ModelPlacement placement{model.get(), Pose::Identity()};
  for (auto _ : state) {
    auto pairs = pairing->nearest(*data, {&placement, 1}, SearchMethod::kExact, {kMaxPairDistCm});
    benchmark::DoNotOptimize(pairs.data());
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations() * in.queries.size()));
}
BENCHMARK_CAPTURE(BM_NearestNeighbour_minemap_queries_only, lidar, "lidar")->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_NearestNeighbour_minemap_queries_only, mine, "mine")->Unit(benchmark::kMillisecond)->UseRealTime();

// ---- Readers: the real mine clouds (binary_compressed PCD) and a paper-size uos text scan ----
void BM_ReadPcdCompressed(benchmark::State& state) {
  const auto path = shared_data() / "mine_jinchuan_pcr" / "2025-04-21-11-04-46.pcd";
  for (auto _ : state) {
    const Scan scan = io::read_pcd(path);
    benchmark::DoNotOptimize(scan.points_cm.data());
    state.SetItemsProcessed(state.items_processed() + static_cast<std::int64_t>(scan.size()));
  }
}
BENCHMARK(BM_ReadPcdCompressed)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ReadUosText(benchmark::State& state) {
  const auto path = std::filesystem::temp_directory_path() / "minemap-bench-scan000.3d";
  io::write_uos_points(path, simulated_pair().model);
  for (auto _ : state) {
    const Scan scan = io::read_uos_points(path);
    benchmark::DoNotOptimize(scan.points_cm.data());
    state.SetItemsProcessed(state.items_processed() + static_cast<std::int64_t>(scan.size()));
  }
  std::filesystem::remove(path);
}
BENCHMARK(BM_ReadUosText)->Unit(benchmark::kMillisecond)->UseRealTime();

// ---- Fig. 5: registration time of two scans against bucket size ----

void BM_RegistrationBucketSize(benchmark::State& state, SearchMethod method) {
  const auto& pair = simulated_pair();
  KdTreeSettings tree;
  tree.bucket_size = static_cast<int>(state.range(0));
  auto pairing = make_cpu_backend();
  SliceFilterSettings filter;
  auto model_points = filter_scan_cpu(pair.model, filter).points_cm;
  auto data_points = filter_scan_cpu(pair.data, filter).points_cm;
  IcpSettings icp;
  icp.method = method;
  const Pose start = pair.true_world_from_model * (rigid_inverse(pair.model.pose_cm) * pair.data.pose_cm);
  IcpResult last;
  for (auto _ : state) {
    // The tree build is part of the registration time, as in the paper.
    auto model = pairing->prepare(model_points, tree);
    auto data = pairing->prepare(data_points, tree);
    const WorldModel placed{model.get(), pair.true_world_from_model};
    last = register_icp(*pairing, *data, start, {&placed, 1}, icp);
    benchmark::DoNotOptimize(last.world_from_data.data());
  }
  state.counters["iterations"] = last.iterations();
  state.counters["bucket_size"] = static_cast<double>(tree.bucket_size);
}
BENCHMARK_CAPTURE(BM_RegistrationBucketSize, exact, SearchMethod::kExact)
    ->Arg(1)->Arg(2)->Arg(5)->Arg(10)->Arg(20)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_RegistrationBucketSize, approximate, SearchMethod::kApproximate)
    ->Arg(1)->Arg(2)->Arg(5)->Arg(10)->Arg(20)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace minemap::bench

BENCHMARK_MAIN();
