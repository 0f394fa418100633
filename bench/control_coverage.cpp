// Survey control (issue 29): does each scan's sigma hold? Simulated surveys (straight, loop, dense;
// several seeds and station counts) are mapped with the defaults, tied to simulated stations, and
// each scan's true position error in the grid is measured against its 95 % ellipsoid (chi-square, 3
// degrees of freedom: 7.81). Prints a Markdown table and writes JSON (--json FILE): the mean error,
// the mean largest sigma, the share inside, and the scale that would put 95 % inside.
//
//   build/bench/control_coverage [--json out/control_coverage.json] [--sigma-scale S] [--set calibration|check|all]
//                                [--free]   (also each survey without control: sigmas relative to scan 0)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/sim/survey_control.hpp"
#include "minemap/slam/control_tie.hpp"
#include "minemap/slam/map_survey.hpp"

namespace {

using namespace minemap;

struct Case {
  const char* set;  ///< "calibration": the surveys the scale was chosen on; "check": the others
  const char* name;
  unsigned seed;
  double loop_cm, step_cm;
  int scans, stations;
  int targets = 0;
};

constexpr Case kCases[] = {
    {"calibration", "straight, seed 1, 3 stations", 1, 0, 400, 0, 3},
    {"calibration", "straight, seed 1, 6 stations", 1, 0, 400, 0, 6},
    {"calibration", "straight, seed 2, 3 stations", 2, 0, 400, 0, 3},
    {"calibration", "straight, seed 2, 6 stations", 2, 0, 400, 0, 6},
    {"calibration", "straight, seed 3, 4 stations", 3, 0, 400, 0, 4},
    {"calibration", "loop 120 m, seed 1, 4 stations", 1, 12000, 400, 0, 4},
    {"calibration", "loop 200 m, seed 7, 5 stations", 7, 20000, 400, 0, 5},
    {"calibration", "dense (1 m steps), seed 1, 40 scans, 4 stations", 1, 0, 100, 40, 4},
    {"calibration", "loop 200 m, seed 3, 6 stations", 3, 20000, 400, 0, 6},
    {"calibration", "straight, seed 4, 3 stations", 4, 0, 400, 0, 3},
    {"calibration", "straight, seed 5, 6 stations", 5, 0, 400, 0, 6},
    {"check", "straight, seed 6, 3 stations", 6, 0, 400, 0, 3},
    {"check", "straight, seed 7, 5 stations", 7, 0, 400, 0, 5},
    {"check", "straight, seed 8, 8 stations", 8, 0, 400, 0, 8},
    {"check", "loop 200 m, seed 2, 5 stations", 2, 20000, 400, 0, 5},
    {"check", "loop 160 m, seed 5, 4 stations", 5, 16000, 400, 0, 4},
    {"check", "dense (1 m steps), seed 2, 60 scans, 5 stations", 2, 0, 100, 60, 5},
    {"check", "straight, seed 1, 5 targets", 1, 0, 400, 0, 0, 5},
    {"check", "straight, seed 9, 3 stations and 4 targets", 9, 0, 400, 0, 3, 4},
    {"check", "loop 200 m, seed 7, 6 targets", 7, 20000, 400, 0, 0, 6},
};

}  // namespace

int main(int argc, char** argv) {
  std::string json_path, set = "all";
  bool free_too = false;  // --free: also the same survey without control, its sigmas held at scan 0
  double sigma_scale = ControlSettings{}.sigma_scale;
  for (int i = 1; i < argc; ++i) {
    const bool value = i + 1 < argc;
    if (!std::strcmp(argv[i], "--free")) free_too = true;
    else if (!std::strcmp(argv[i], "--json") && value) json_path = argv[++i];
    else if (!std::strcmp(argv[i], "--sigma-scale") && value) sigma_scale = std::stod(argv[++i]);
    else if (!std::strcmp(argv[i], "--set") && value) set = argv[++i];
    else {
      std::fprintf(stderr, "usage: control_coverage [--json FILE] [--sigma-scale S] [--set calibration|check|all|NAME] [--free]\n");
      return 2;
    }
  }
  std::printf("| set | survey | scans | mean error cm | mean largest sigma cm | inside 95 %% | scale for 95 %% |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  std::string json = "[\n";
  std::size_t inside_all = 0, scans_all = 0;
  for (const Case& c : kCases) {
    if (set != "all" && set != c.set && set != c.name) continue;
    sim::SimulationSettings settings;
    settings.mine.seed = c.seed;
    settings.mine.loop_length_cm = c.loop_cm;
    settings.mine.mean_step_cm = c.step_cm;
    settings.mine.scans = c.scans;
    const sim::SimulatedSurvey survey = sim::simulate_mine_survey(settings);
    MappingSettings mapping;
    mapping.control.keep_graph = true;
    mapping.control.sigma_scale = sigma_scale;
    CpuBackend cpu;
    MappingResult result = map_survey(survey.scans, mapping, cpu);
    std::vector<std::string> names;
    for (const Scan& scan : survey.scans) names.push_back(scan.name);
    sim::ControlSimulationSettings stations;
    stations.stations = c.stations;
    stations.targets = c.targets;
    stations.seed = c.seed;
    const sim::SimulatedControl control = sim::simulate_control(survey.truth_cm, names, stations, settings.mine);
    tie_to_control(result, control.file, true, mapping.control, mapping.loops.graph);
    if (free_too) {
      // Without control: the graph held at scan 0, each scan's error relative to it.
      std::vector<Pose> poses;
      for (const ScanOutcome& s : result.scans) poses.push_back(s.world_from_points);
      std::vector<std::size_t> all(poses.size());
      for (std::size_t k = 0; k < all.size(); ++k) all[k] = k;
      MappingResult free_result = map_survey(survey.scans, mapping, cpu);
      std::vector<Pose> free_poses;
      for (const ScanOutcome& s : free_result.scans) free_poses.push_back(s.world_from_points);
      const auto cov = pose_graph_covariances(free_poses, free_result.graph, {}, {}, 0, mapping.loops.graph, all);
      std::size_t in = 0;
      double err_sum = 0, sig_sum = 0;
      std::vector<double> free_d2;
      const Pose to_truth = survey.truth_cm[0] * rigid_inverse(free_result.scans[0].pose_cm);
      for (std::size_t k = 0; k < all.size(); ++k) {
        const Eigen::Vector3d e = (to_truth * free_result.scans[k].pose_cm).block<3, 1>(0, 3) - survey.truth_cm[k].block<3, 1>(0, 3);
        const Eigen::Matrix3d r = to_truth.block<3, 3>(0, 0) * free_poses[k].block<3, 3>(0, 0);
        const Eigen::Matrix3d c3 = sigma_scale * sigma_scale * r * cov[k].topLeftCorner<3, 3>() * r.transpose();
        if (k > 0 && e.dot(c3.ldlt().solve(e)) <= 7.81) ++in;
        if (k > 0) free_d2.push_back(e.dot(c3.ldlt().solve(e)));
        err_sum += e.norm();
        sig_sum += std::sqrt(c3.trace());
      }
      std::sort(free_d2.begin(), free_d2.end());
      std::printf("  free: inside %.0f %% of %zu, mean error %.1f cm, mean sigma %.1f cm, scale for 95 %% %.3f\n", 100.0 * in / (all.size() - 1), all.size() - 1, err_sum / all.size(), sig_sum / all.size(), sigma_scale * std::sqrt(free_d2[free_d2.size() * 95 / 100] / 7.81));
    }
    if (std::getenv("MINEMAP_DEBUG_CONTROL")) {  // each point's residual
      for (const ControlResidual& r : result.control->residuals) {
        std::printf("  %s: %.1f mm, %.2f sigmas%s\n", r.point.c_str(), 1000 * r.residual_m.norm(), r.sigmas, r.blunder ? " blunder" : "");
      }
    }
    std::vector<double> d2;
    double error_sum = 0.0, sigma_sum = 0.0;
    for (std::size_t k = 0; k < result.scans.size(); ++k) {
      const Pose& truth = survey.truth_cm[k];
      const Eigen::Vector3d grid = control.grid_from_mine_cm.block<3, 3>(0, 0) * truth.block<3, 1>(0, 3) +
                                   control.grid_from_mine_cm.block<3, 1>(0, 3);
      const Eigen::Vector3d error =
          result.scans[k].pose_cm.block<3, 1>(0, 3) - (grid_to_survey_axes(grid, true) - result.control->origin_cm);
      const Eigen::Matrix3d r = result.scans[k].world_from_points.block<3, 3>(0, 0);
      const Eigen::Matrix3d c3 = r * result.scans[k].covariance->topLeftCorner<3, 3>() * r.transpose();
      d2.push_back(error.dot(c3.ldlt().solve(error)));
      error_sum += error.norm();
      sigma_sum += scan_sigma(result.scans[k]).axes_cm.x();
    }
    const std::size_t inside = static_cast<std::size_t>(std::count_if(d2.begin(), d2.end(), [](double v) { return v <= 7.81; }));
    std::vector<double> sorted = d2;
    std::sort(sorted.begin(), sorted.end());
    const double q95 = sorted[sorted.size() * 95 / 100];
    const double n = static_cast<double>(d2.size());
    inside_all += inside;
    scans_all += d2.size();
    std::printf("| %s | %s | %zu | %.1f | %.1f | %.0f %% | %.2f |\n", c.set, c.name, d2.size(), error_sum / n,
                sigma_sum / n, 100.0 * inside / n, sigma_scale * std::sqrt(q95 / 7.81));
    char line[512];
    std::snprintf(line, sizeof line,
                  "  {\"set\": \"%s\", \"survey\": \"%s\", \"scans\": %zu, \"mean_error_cm\": %.3f, "
                  "\"mean_largest_sigma_cm\": %.3f, \"inside_95\": %.4f, \"scale_for_95\": %.4f},\n",
                  c.set, c.name, d2.size(), error_sum / n, sigma_sum / n, inside / n, sigma_scale * std::sqrt(q95 / 7.81));
    json += line;
  }
  if (json.size() > 2) json.erase(json.size() - 2, 1);
  json += "]\n";
  std::printf("\nall: %zu of %zu scans inside their 95 %% ellipsoid (%.1f %%), sigma scale %.2f\n", inside_all, scans_all,
              100.0 * static_cast<double>(inside_all) / static_cast<double>(std::max<std::size_t>(1, scans_all)), sigma_scale);
  if (!json_path.empty()) std::ofstream(json_path) << json;
  return 0;
}
