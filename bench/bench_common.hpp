#pragma once
// Inputs shared by the benchmark programs: the simulated paper-size scans and the shared real scans.
#include <filesystem>
#include <fstream>
#include <memory>
#include <vector>

#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <cstdlib>

#include "minemap/backend/make_backend.hpp"
#include "minemap/filter/slice_filter.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace minemap::bench {

/// Two consecutive simulated mine scans of the paper's size (361 x 341), seed 1, with true poses.
struct SimulatedPair {
  Scan model, data;
  Pose true_world_from_model, true_world_from_data;
};
inline const SimulatedPair& simulated_pair() {
  static const SimulatedPair pair = [] {
    sim::SimulationSettings settings;
    settings.mine.scans = 2;
    settings.mine.seed = 1;
    auto survey = sim::simulate_mine_survey(settings);
    return SimulatedPair{survey.scans[0], survey.scans[1], survey.truth_cm[0], survey.truth_cm[1]};
  }();
  return pair;
}

/// The requested backend (MINEMAP_OPENCL_DEVICE and the other variables of
/// backend_options_from_environment apply), or nullptr after marking the benchmark skipped (e.g. no
/// OpenCL).
inline std::unique_ptr<ComputeBackend> backend_or_skip(benchmark::State& state, Backend backend) {
  try {
    return make_backend(backend_options_from_environment(backend)).backend;
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
    return nullptr;
  }
}

inline std::filesystem::path shared_data() { return MINEMAP_SHARED_DATA_DIR; }

/// MINEMAP_BENCH_THREADS=N caps TBB at N threads for the whole program (unset: all cores).
/// bench/count_instructions.py runs rows on one thread under callgrind, where worker threads'
/// spin-waiting would make the instruction counts vary from run to run.
inline const std::unique_ptr<tbb::global_control> thread_limit = []() -> std::unique_ptr<tbb::global_control> {
  const char* text = std::getenv("MINEMAP_BENCH_THREADS");
  const int threads = text ? std::atoi(text) : 0;
  if (threads <= 0) return nullptr;
  return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                               static_cast<std::size_t>(threads));
}();

/// ../shared/data/fast_gicp_pair: target, source (about 69k points each), cm.
struct RealPair {
  Scan target, source;
};
inline const RealPair& fast_gicp_pair() {
  static const RealPair pair = [] {
    const auto dir = shared_data() / "fast_gicp_pair";
    return RealPair{io::read_pcd(dir / "251370668.pcd"), io::read_pcd(dir / "251371071.pcd")};
  }();
  return pair;
}

}  // namespace minemap::bench
