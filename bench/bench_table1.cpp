// The paper's Table I: time and ICP iterations to align two scans, per search method and data
// reduction, plus simultaneous matching of a whole survey. Rows (benchmark names):
//   BM_Table1_Pair/<data>/<backend>/all_brute   all points, brute force: ONE iteration is timed
//                                               (counter iterations_timed=1); the table multiplies
//                                               by the kd row's iterations and says so
//   BM_Table1_Pair/<data>/<backend>/all_kd      all points, exact kd-tree
//   BM_Table1_Pair/<data>/<backend>/all_apx     all points, approximate kd-tree then exact
//   BM_Table1_Pair/<data>/<backend>/reduced_apx reduced points (slice filter, or every 4th point for
//                                               scans without slices), approximate then exact
//   BM_Table1_Pair/<data>/<backend>/*_accelerated  the same with Anderson-accelerated ICP
//                                               (IcpSettings::accelerate; not in the paper):
//                                               all_kd, reduced_kd (exact only) and reduced_apx
//   BM_Table1_Slam/<backend>/<scans>            simultaneous matching of the simulated survey, the
//                                               paper's setting (models reduced like the data)
//   BM_Table1_Slam/cpu_dense_models/<scans>     the same with minemap's defaults: denser models and
//                                               Anderson-accelerated ICP
// <data>: mine (two consecutive simulated 361 x 341 scans, from odometry) or lidar
// (../shared/data/fast_gicp_pair, from the reference perturbed by ~10 cm / 0.4 deg).
// Times include building the trees, as the paper's do. bench/run_benchmarks.sh makes the table.
#include <benchmark/benchmark.h>

#include <cstdlib>

#include "bench_common.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/slam/survey_matching.hpp"

namespace minemap::bench {
namespace {

struct PairInput {
  std::vector<Eigen::Vector3f> model_all, data_all, model_reduced, data_reduced;
  Pose world_from_model = Pose::Identity();
  Pose start_world_from_data = Pose::Identity();
};

const PairInput& pair_input(const std::string& data) {
  static const PairInput mine = [] {
    const auto& pair = simulated_pair();
    PairInput in;
    in.model_all = pair.model.points_cm;
    in.data_all = pair.data.points_cm;
    in.model_reduced = filter_scan_cpu(pair.model, {}).points_cm;
    in.data_reduced = filter_scan_cpu(pair.data, {}).points_cm;
    in.world_from_model = pair.true_world_from_model;
    // 3DTK's start: the odometry step applied to the model's (registered) pose.
    in.start_world_from_data = pair.true_world_from_model * rigid_inverse(pair.model.pose_cm) * pair.data.pose_cm;
    return in;
  }();
  static const PairInput lidar = [] {
    const auto& pair = fast_gicp_pair();
    PairInput in;
    in.model_all = pair.target.points_cm;
    in.data_all = pair.source.points_cm;
    in.model_reduced = thin_unstructured(pair.target, 4);
    in.data_reduced = thin_unstructured(pair.source, 4);
    in.world_from_model = pair.target.world_from_points();
    std::ifstream file(shared_data() / "fast_gicp_pair" / "relative.txt");
    Pose reference;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) file >> reference(r, c);
    reference.block<3, 1>(0, 3) *= 100.0;
    in.start_world_from_data = in.world_from_model * reference *
                               euler_to_pose({Eigen::Vector3d(8.0, -5.0, 4.0), Eigen::Vector3d(0.1, 0.3, -0.2)});
    return in;
  }();
  return data == "mine" ? mine : lidar;
}

/// One row of Table I: which points, which search, plain or accelerated ICP.
struct Row {
  const char* name;
  bool reduced;
  SearchMethod method;
  bool accelerate;
};
constexpr Row kRows[] = {
    {"all_brute", false, SearchMethod::kBruteForce, false},
    {"all_kd", false, SearchMethod::kExact, false},
    {"all_apx", false, SearchMethod::kApproximate, false},
    {"reduced_apx", true, SearchMethod::kApproximate, false},
    {"all_kd_accelerated", false, SearchMethod::kExact, true},
    {"reduced_kd_accelerated", true, SearchMethod::kExact, true},
    {"reduced_apx_accelerated", true, SearchMethod::kApproximate, true},
};

void BM_Table1_Pair(benchmark::State& state, std::string data, Backend backend, Row row) {
  const PairInput& in = pair_input(data);
  auto pairing = backend_or_skip(state, backend);
  if (!pairing) return;
  const bool reduced = row.reduced;
  const bool brute = row.method == SearchMethod::kBruteForce;
  IcpSettings icp = IcpSettings::paper();
  icp.method = row.method;
  icp.accelerate = row.accelerate;
  if (brute) icp.termination.max_iterations = 1;  // one timed iteration; see the header
  icp.termination.min_pairs = 3;
  IcpResult last;
  for (auto _ : state) {
    auto model = pairing->prepare(reduced ? in.model_reduced : in.model_all, {});
    auto data_cloud = pairing->prepare(reduced ? in.data_reduced : in.data_all, {});
    const WorldModel placed{model.get(), in.world_from_model};
    last = register_icp(*pairing, *data_cloud, in.start_world_from_data, {&placed, 1}, icp);
    benchmark::DoNotOptimize(last.world_from_data.data());
  }
  state.counters["icp_iterations"] = last.iterations();
  state.counters["approximate_iterations"] = last.approximate_iterations;
  state.counters["exact_iterations"] = last.exact_iterations;
  state.counters["iterations_timed"] = last.iterations();
  state.counters["pairs"] = static_cast<double>(last.pairs);
  state.counters["model_points"] = static_cast<double>((reduced ? in.model_reduced : in.model_all).size());
  state.counters["rms_cm"] = last.rms_cm;
  state.counters["accelerations"] = last.accelerations;
  state.counters["rejected_accelerations"] = last.rejected_accelerations;
  const EulerPose final_pose = pose_to_euler(last.world_from_data);
  for (int i = 0; i < 3; ++i) {
    state.counters["final_t" + std::to_string(i) + "_cm"] = final_pose.position_cm[i];
    state.counters["final_r" + std::to_string(i) + "_deg"] = final_pose.angles_deg[i];
  }
}

void register_pair_rows() {
  for (const std::string data : {"mine", "lidar"}) {
    for (const auto& [backend_name, backend] : {std::pair{"cpu", Backend::kCpu}, std::pair{"opencl", Backend::kOpenCl}}) {
      for (const Row& row : kRows) {
        const std::string name = "BM_Table1_Pair/" + data + "/" + backend_name + "/" + row.name;
        auto* b = benchmark::RegisterBenchmark(name.c_str(), BM_Table1_Pair, data, backend, row);
        b->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(row.method == SearchMethod::kBruteForce ? 1 : 3);
      }
    }
  }
}

void BM_Table1_Slam(benchmark::State& state, Backend backend, const MappingSettings& mapping) {
  sim::SimulationSettings settings;
  settings.mine.scans = static_cast<int>(state.range(0));
  const auto survey = sim::simulate_mine_survey(settings);
  auto compute = backend_or_skip(state, backend);
  if (!compute) return;
  MappingResult result;
  for (auto _ : state) {
    try {
      result = map_survey(survey.scans, mapping, *compute);
    } catch (const std::exception& e) {
      state.SkipWithError(e.what());
      return;
    }
  }
  state.counters["step1_icp_iterations"] = result.step1_icp_iterations;
  state.counters["step3_icp_iterations"] = result.step3_icp_iterations;
  state.counters["relaxation_matches"] = result.relaxation_matches;
  std::vector<Pose> poses;
  for (const auto& s : result.scans) poses.push_back(s.pose_cm);
  const auto errors = pose_errors(poses, survey.truth_cm);
  state.counters["mean_error_cm"] = errors.mean_translation_cm;
  state.counters["path_cm"] = errors.path_length_cm;
}

void register_slam_rows() {
  const int scans = std::getenv("MINEMAP_BENCH_SLAM_SCANS") ? std::atoi(std::getenv("MINEMAP_BENCH_SLAM_SCANS")) : 48;
  for (const auto& [backend_name, backend] : {std::pair{"cpu", Backend::kCpu}, std::pair{"opencl", Backend::kOpenCl}}) {
    benchmark::RegisterBenchmark(("BM_Table1_Slam/" + std::string(backend_name)).c_str(), BM_Table1_Slam, backend,
                                 MappingSettings::paper())
        ->Arg(scans)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);
  }
  // The paper's relaxation with minemap's ICP, against models that keep every slice.
  benchmark::RegisterBenchmark("BM_Table1_Slam/cpu_dense_models", BM_Table1_Slam, Backend::kCpu,
                               MappingSettings::simultaneous())
      ->Arg(scans)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);
  // minemap's default: voxel means, each scan matched once against the metascan.
  benchmark::RegisterBenchmark("BM_Table1_Slam/cpu_default", BM_Table1_Slam, Backend::kCpu, MappingSettings{})
      ->Arg(scans)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);
}

}  // namespace
}  // namespace minemap::bench

int main(int argc, char** argv) {
  minemap::bench::register_pair_rows();
  minemap::bench::register_slam_rows();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
