// Survey control (issue 29): the control file's reader refuses bad files by file and line; a
// simulated survey tied to its stations lands in the grid (rotated, UTM-size offset) within its
// relative error plus the control's sigma, its far end closer than without control; a planted
// blunder is named, left out, and the map stays right elsewhere; each scan's sigma covers its error.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "io_test_helpers.hpp"
#include "minemap/backend/cpu_backend.hpp"
#include "minemap/core/error.hpp"
#include "minemap/io/control.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/sim/survey_control.hpp"
#include "minemap/slam/control_tie.hpp"
#include "minemap/slam/map_survey.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

std::filesystem::path write_text(const test::TempDir& dir, const std::string& text) {
  const std::filesystem::path path = dir.path() / "control.txt";
  std::ofstream(path) << text;
  return path;
}

/// The InputError reading `text` gives: its line and kind.
InputError error_of(const std::string& text) {
  const test::TempDir dir;
  try {
    (void)io::read_control(write_text(dir, text));
  } catch (const InputError& e) {
    return e;
  }
  ADD_FAILURE() << "no error for:\n" << text;
  return InputError({}, "none");
}

TEST(ControlFile, ReadsPointsStationsTargetsAndTheCrs) {
  const test::TempDir dir;
  const auto path = write_text(dir,
                               "# a mine's control\n"
                               "crs EPSG:32633\n"
                               "station scan003 M1 0.8   # over M1\n"
                               "point M1 512345.678 6712345.678 1234.5 0.005\n"
                               "point T4 512300 6712300 1230 0.004 0.010\n"
                               "\n"
                               "target scan010 T4 1.5 -2.0 3.25\n");
  const io::ControlFile control = io::read_control(path);
  ASSERT_TRUE(control.epsg);
  EXPECT_EQ(*control.epsg, 32633u);
  ASSERT_EQ(control.points.size(), 2u);
  EXPECT_EQ(control.points[0].grid_m, Eigen::Vector3d(512345.678, 6712345.678, 1234.5));
  EXPECT_EQ(control.points[0].sigma_vertical_m, 0.005);
  EXPECT_EQ(control.points[1].sigma_horizontal_m, 0.004);
  EXPECT_EQ(control.points[1].sigma_vertical_m, 0.010);
  ASSERT_EQ(control.observations.size(), 2u);
  EXPECT_EQ(control.observations[0].kind, io::ControlObservation::Kind::kStation);
  EXPECT_EQ(control.observations[0].point, 0u);
  EXPECT_DOUBLE_EQ(control.observations[0].instrument_height_cm, 80.0);
  EXPECT_EQ(control.observations[1].kind, io::ControlObservation::Kind::kTarget);
  EXPECT_EQ(control.observations[1].scan, "scan010");
  EXPECT_EQ(control.observations[1].in_scan_cm, Eigen::Vector3d(150.0, -200.0, 325.0));  
  EXPECT_EQ(control.observations[1].line, 7);

  const std::vector<std::string> names{"scan003", "scan010"};
  EXPECT_NO_THROW(io::check_control_scans(control, names));
  const std::vector<std::string> other{"scan003"};
  try {
    io::check_control_scans(control, other);
    ADD_FAILURE() << "an unknown scan passed";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where().line, 7);
    EXPECT_NE(std::string(e.what()).find("scan010"), std::string::npos) << e.what();
  }
}

TEST(ControlFile, RefusesBadFilesByLine) {
  const std::string point = "point M1 1 2 3 0.01\n";
  const std::string station = "station scan000 M1\n";
  struct Case {
    std::string text;
    std::int64_t line;
    InputProblem problem;
    const char* says;
  };
  const Case cases[] = {
      {point + "stations scan000 M1\n", 2, InputProblem::kMalformed, "unknown record"},
      {"point M1 1 nan 3 0.01\n" + station, 1, InputProblem::kNonFinite, "not finite"},
      {"point M1 1 2 3\n" + station, 1, InputProblem::kMalformed, "found 4"},
      {"point M1 1 2 x 0.01\n" + station, 1, InputProblem::kMalformed, "not a number"},
      {"point M1 1 2 3 0\n" + station, 1, InputProblem::kMalformed, "more than 0"},
      {point + point + station, 2, InputProblem::kInconsistentSurvey, "defined twice"},
      {"crs UTM33\n" + point + station, 1, InputProblem::kMalformed, "not an EPSG code"},
      {"crs 32633\ncrs 32633\n" + point + station, 2, InputProblem::kMalformed, "second crs"},
      {point + "station scan000 M2\n", 2, InputProblem::kInconsistentSurvey, "no point line defines"},
      {point + "target scan000 M1 1 2\n", 2, InputProblem::kMalformed, "found 4"},
      {point, 0, InputProblem::kEmpty, "no station or target"},
  };
  for (const Case& c : cases) {
    const InputError e = error_of(c.text);
    EXPECT_EQ(e.where().line, c.line) << c.text << e.what();
    EXPECT_EQ(e.problem(), c.problem) << c.text << e.what();
    EXPECT_NE(std::string(e.what()).find(c.says), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("control.txt"), std::string::npos) << e.what();
  }
}

/// A simulated straight drive mapped once (shared by the tie tests: mapping is what costs).
struct MappedDrive {
  sim::SimulatedSurvey survey;
  MappingResult result;
  std::vector<std::string> names;
};

const MappedDrive& mapped_drive() {
  static const MappedDrive drive = [] {
    MappedDrive d;
    sim::SimulationSettings settings;
    settings.mine.seed = 1;
    d.survey = sim::simulate_mine_survey(settings);
    MappingSettings mapping;
    mapping.control.keep_graph = true;
    CpuBackend cpu;
    d.result = map_survey(d.survey.scans, mapping, cpu);
    for (const Scan& scan : d.survey.scans) d.names.push_back(scan.name);
    return d;
  }();
  return drive;
}

/// Each scan's position error (cm) in the grid's local frame against the truth placed in the grid.
std::vector<double> grid_errors(const MappingResult& tied, const sim::SimulatedSurvey& survey,
                                const sim::SimulatedControl& control) {
  std::vector<double> errors;
  for (std::size_t k = 0; k < tied.scans.size(); ++k) {
    const Pose& truth = survey.truth_cm[k];
    const Eigen::Vector3d grid =
        control.grid_from_mine_cm.block<3, 3>(0, 0) * truth.block<3, 1>(0, 3) + control.grid_from_mine_cm.block<3, 1>(0, 3);
    const Eigen::Vector3d expected = grid_to_survey_axes(grid, true) - tied.control->origin_cm;
    errors.push_back((tied.scans[k].pose_cm.block<3, 1>(0, 3) - expected).norm());
  }
  return errors;
}

/// The same without control: the map in the first scan's frame, placed by the first scan's truth.
std::vector<double> first_scan_errors(const MappingResult& result, const sim::SimulatedSurvey& survey) {
  std::vector<double> errors;
  const Pose to_truth = survey.truth_cm[0] * rigid_inverse(result.scans[0].pose_cm);
  for (std::size_t k = 0; k < result.scans.size(); ++k) {
    errors.push_back(((to_truth * result.scans[k].pose_cm).block<3, 1>(0, 3) - survey.truth_cm[k].block<3, 1>(0, 3)).norm());
  }
  return errors;
}

double mean_of(const std::vector<double>& v, std::size_t from = 0) {
  double sum = 0.0;
  for (std::size_t k = from; k < v.size(); ++k) sum += v[k];
  return sum / static_cast<double>(v.size() - from);
}

/// The share of scans whose true position error lies inside their 95 % ellipsoid (chi-square, 3
/// degrees of freedom: 7.81), from each scan's covariance.
double coverage_95(const MappingResult& tied, const std::vector<double>&, const sim::SimulatedSurvey& survey,
                   const sim::SimulatedControl& control) {
  std::size_t inside = 0;
  for (std::size_t k = 0; k < tied.scans.size(); ++k) {
    const Pose& truth = survey.truth_cm[k];
    const Eigen::Vector3d grid =
        control.grid_from_mine_cm.block<3, 3>(0, 0) * truth.block<3, 1>(0, 3) + control.grid_from_mine_cm.block<3, 1>(0, 3);
    const Eigen::Vector3d expected = grid_to_survey_axes(grid, true) - tied.control->origin_cm;
    const Eigen::Vector3d error = tied.scans[k].pose_cm.block<3, 1>(0, 3) - expected;
    const Eigen::Matrix3d r = tied.scans[k].world_from_points.block<3, 3>(0, 0);
    const Eigen::Matrix3d c = r * tied.scans[k].covariance->topLeftCorner<3, 3>() * r.transpose();
    inside += error.dot(c.ldlt().solve(error)) <= 7.81 ? 1 : 0;
  }
  return static_cast<double>(inside) / static_cast<double>(tied.scans.size());
}

TEST(ControlTie, AStraightDriveTiedToItsStationsLandsInTheGrid) {
  const MappedDrive& drive = mapped_drive();
  for (const int stations : {3, 6}) {
    sim::ControlSimulationSettings settings;
    settings.stations = stations;
    const sim::SimulatedControl control = sim::simulate_control(drive.survey.truth_cm, drive.names, settings);
    MappingResult tied = drive.result;
    tie_to_control(tied, control.file, true, ControlSettings{}, LoopClosureSettings{}.graph);
    ASSERT_TRUE(tied.control);
    const std::vector<double> grid = grid_errors(tied, drive.survey, control);
    const std::vector<double> free = first_scan_errors(drive.result, drive.survey);
    const std::size_t far_end = grid.size() * 9 / 10;
    std::printf("%d stations: grid mean %.1f cm, far end %.1f cm; without control mean %.1f, far end %.1f; rms %.1f mm, bent max %.1f cm\n",
                stations, mean_of(grid), mean_of(grid, far_end), mean_of(free), mean_of(free, far_end),
                1000.0 * tied.control->rms_m, tied.control->bent_max_cm);
    for (const ControlResidual& r : tied.control->residuals) {
      std::printf("  %s: E %+.1f N %+.1f H %+.1f mm (%.2f sigmas)%s\n", r.point.c_str(), 1000 * r.residual_m.x(),
                  1000 * r.residual_m.y(), 1000 * r.residual_m.z(), r.sigmas, r.blunder ? " blunder" : "");
    }
    const double coverage = coverage_95(tied, grid, drive.survey, control);
    std::printf("  coverage %.2f\n", coverage);
    EXPECT_TRUE(tied.doubtful().empty());
    EXPECT_EQ(tied.control->points_used, stations);
    EXPECT_EQ(tied.control->checked_for_blunders, stations >= 4);
    // In the grid within the map's own error plus the control's sigma, the far end at least twice
    // as close as the map placed by its first scan alone.
    EXPECT_LE(mean_of(grid), mean_of(free) + 0.5);
    EXPECT_LE(2.0 * mean_of(grid, far_end), mean_of(free, far_end));
    for (const ControlResidual& r : tied.control->residuals) EXPECT_LT(r.sigmas, 1.0) << r.point;
    // The sigma holds: 90-99 % of the true errors inside their 95 % ellipsoids, neither
    // overconfident nor uselessly wide (bench/control_coverage: 17 surveys).
    EXPECT_GE(coverage, 0.9);
    EXPECT_LE(coverage, 0.99);
  }
}

TEST(ControlTie, ABlunderIsNamedAndLeftOut) {
  const MappedDrive& drive = mapped_drive();
  sim::ControlSimulationSettings settings;
  settings.stations = 6;
  settings.blunder_m = 0.5;
  const sim::SimulatedControl control = sim::simulate_control(drive.survey.truth_cm, drive.names, settings);
  MappingResult tied = drive.result;
  tie_to_control(tied, control.file, true, ControlSettings{}, LoopClosureSettings{}.graph);
  const std::vector<double> grid = grid_errors(tied, drive.survey, control);
  std::printf("blunder %s: grid mean %.1f cm max %.1f; coverage %.2f\n", control.blunder.c_str(), mean_of(grid),
              *std::max_element(grid.begin(), grid.end()), coverage_95(tied, grid, drive.survey, control));
  for (const ControlResidual& r : tied.control->residuals) {
    std::printf("  %s: E %+.1f N %+.1f H %+.1f mm (%.2f sigmas)%s\n", r.point.c_str(), 1000 * r.residual_m.x(),
                1000 * r.residual_m.y(), 1000 * r.residual_m.z(), r.sigmas, r.blunder ? " blunder" : "");
  }
  const std::vector<std::size_t> doubtful = tied.doubtful();
  for (std::size_t k : doubtful) std::printf("  doubtful %s: %s\n", tied.scans[k].name.c_str(), tied.scans[k].health.doubt.c_str());
  // Named by its residual (about the 0.5 m planted), left out; the map within 3 cm of the truth.
  ASSERT_EQ(control.blunder, "S4");
  EXPECT_EQ(tied.control->points_used, 5);
  for (const ControlResidual& r : tied.control->residuals) {
    EXPECT_EQ(r.blunder, r.point == "S4") << r.point;
    if (r.blunder) {
      EXPECT_NEAR(r.residual_m.norm(), 0.5, 0.05);
    }
  }
  ASSERT_EQ(doubtful.size(), 1u);
  EXPECT_NE(tied.scans[doubtful[0]].health.doubt.find("control point S4"), std::string::npos);
  EXPECT_LT(mean_of(grid), 3.0);
  EXPECT_LT(*std::max_element(grid.begin(), grid.end()), 5.0);
}

// Targets on the ribs, each picked in one scan, tie the map as stations do (and, off the drive's
// line, pin its roll too).
TEST(ControlTie, TargetsOnTheRibsTieTheMapToo) {
  const MappedDrive& drive = mapped_drive();
  sim::ControlSimulationSettings settings;
  settings.targets = 5;
  sim::SimulationSettings simulation;
  simulation.mine.seed = 1;
  const sim::SimulatedControl control = sim::simulate_control(drive.survey.truth_cm, drive.names, settings, simulation.mine);
  ASSERT_EQ(control.file.points.size(), 5u);
  for (const io::ControlObservation& o : control.file.observations) {
    EXPECT_EQ(o.kind, io::ControlObservation::Kind::kTarget);
    EXPECT_GT(o.in_scan_cm.norm(), 100.0);  // on the rib, metres off the scanner
  }
  MappingResult tied = drive.result;
  tie_to_control(tied, control.file, true, ControlSettings{}, LoopClosureSettings{}.graph);
  const std::vector<double> grid = grid_errors(tied, drive.survey, control);
  const std::vector<double> free = first_scan_errors(drive.result, drive.survey);
  const std::size_t far_end = grid.size() * 9 / 10;
  std::printf("targets: grid mean %.1f cm, far end %.1f cm (without control %.1f / %.1f)\n", mean_of(grid),
              mean_of(grid, far_end), mean_of(free), mean_of(free, far_end));
  EXPECT_TRUE(tied.doubtful().empty());
  EXPECT_LE(mean_of(grid), mean_of(free) + 0.5);
  EXPECT_LE(2.0 * mean_of(grid, far_end), mean_of(free, far_end));
}

TEST(ControlTie, RefusesTooFewPointsOrPointsInALine) {
  const MappedDrive& drive = mapped_drive();
  sim::ControlSimulationSettings settings;
  settings.stations = 3;
  sim::SimulatedControl control = sim::simulate_control(drive.survey.truth_cm, drive.names, settings);
  io::ControlFile two = control.file;
  two.observations.pop_back();
  MappingResult tied = drive.result;
  EXPECT_THROW(tie_to_control(tied, two, true, ControlSettings{}, LoopClosureSettings{}.graph), InputError);
  io::ControlFile line = control.file;
  for (io::ControlPoint& p : line.points) p.grid_m = Eigen::Vector3d(1000.0, 2000.0, 0.0) + p.grid_m.x() * Eigen::Vector3d(1, 0, 0);
  EXPECT_THROW(tie_to_control(tied, line, true, ControlSettings{}, LoopClosureSettings{}.graph), InputError);
  io::ControlFile unknown = control.file;
  unknown.observations[0].scan = "scan999";
  unknown.observations[0].line = 12;
  try {
    tie_to_control(tied, unknown, true, ControlSettings{}, LoopClosureSettings{}.graph);
    ADD_FAILURE() << "an unknown scan was tied";
  } catch (const InputError& e) {
    EXPECT_EQ(e.where().line, 12);
  }
  MappingResult no_graph = drive.result;
  no_graph.graph.clear();
  EXPECT_THROW(tie_to_control(no_graph, control.file, true, ControlSettings{}, LoopClosureSettings{}.graph),
               std::invalid_argument);
}

}  // namespace
}  // namespace minemap
