// `minemap simulate`: the built-in simulated mine survey, written with its truth: the tilting
// scanner's stop-and-go survey as uos (the default), or a moving LiDAR's sweeps as PCD.
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include "minemap/cli/commands.hpp"
#include "minemap/core/error.hpp"
#include "minemap/io/control.hpp"
#include "minemap/sim/survey_control.hpp"

namespace minemap::cli {
namespace {

constexpr const char* kTilting = "tilting";

/// Refuses a folder that holds scans other than the ones about to be written: read back, a stale
/// scan (a longer earlier run's scan250.pcd, a tilting survey's scan000.3d) would join this survey.
void check_no_stale_scans(const fs::path& dir, const std::vector<Scan>& scans) {
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(dir, error)) {
    if (!entry.is_regular_file(error)) continue;
    const fs::path& file = entry.path();
    const std::string extension = file.extension().string();
    const bool ours = extension == ".pcd" && std::any_of(scans.begin(), scans.end(), [&](const Scan& scan) {
                        return file.stem().string() == scan.name;
                      });
    const bool scan_file = extension == ".pcd" || extension == ".3d" || extension == ".ply" ||
                           extension == ".xyz" || extension == ".bin";
    if (scan_file && !ours) {
      throw OutputError("cannot write a survey of " + std::to_string(scans.size()) + " sweeps into " + dir.string() +
                        ": it already holds " + file.filename().string() + " (use an empty folder)");
    }
  }
}

std::vector<io::TimedPose> timed(const std::vector<double>& stamps_s, const std::vector<Pose>& poses_cm) {
  std::vector<io::TimedPose> out;
  out.reserve(poses_cm.size());
  for (std::size_t i = 0; i < poses_cm.size(); ++i) out.push_back({stamps_s[i], poses_cm[i]});
  return out;
}

int run_moving_simulate(const SimulateOptions& options, sim::MovingSensor sensor) {
  if (options.step_given) {
    throw std::invalid_argument("--step-m is the tilting scanner's stop-and-go spacing; a moving sensor sweeps at "
                                "--rate-hz while it moves at --speed-mps");
  }
  if (options.beams && sensor != sim::MovingSensor::kSpinning) {
    throw std::invalid_argument("--beams is the spinning sensor's (--sensor spinning)");
  }
  sim::MovingSimulationSettings settings;
  settings.sensor = sensor;
  settings.sweeps = options.scans;
  settings.mine.seed = options.seed;
  settings.mine.loop_length_cm = 100.0 * options.loop_m;
  settings.speed_mps = options.speed_mps;
  if (options.rate_hz) settings.rate_hz = *options.rate_hz;
  if (options.beams) settings.spinning.beams = *options.beams;
  if (options.turn_deg_s) settings.turn_deg_s = *options.turn_deg_s;
  settings.odometry = options.odometry;

  const auto start = std::chrono::steady_clock::now();
  const sim::MovingSurvey survey = sim::simulate_moving_survey(settings);
  std::error_code error;
  fs::create_directories(options.out, error);
  if (error) throw OutputError("cannot create " + options.out.string() + ": " + error.message());
  check_no_stale_scans(options.out, survey.scans);
  // PCD in metres (binary, x y z intensity time ring): the sensor frame, right-handed, z up. The
  // VIEWPOINT holds the scan's pose: the odometry with --odometry, else the identity.
  std::size_t points = 0;
  for (const Scan& scan : survey.scans) {
    io::write_pcd(options.out / (scan.name + ".pcd"), scan, io::PcdEncoding::kBinary, LengthUnit::kMetre);
    points += scan.size();
  }
  io::write_tum(options.out / "truth.tum", timed(survey.stamps_s, survey.truth_cm), LengthUnit::kMetre);
  if (options.odometry) {
    io::write_tum(options.out / "odometry.tum", timed(survey.stamps_s, survey.odometry_cm), LengthUnit::kMetre);
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("simulated %zu sweeps of a %s LiDAR (%zu points, %.1f m driven at %g m/s, %g Hz) into %s in %.1f s\n",
              survey.scans.size(), name_in(sim::kMovingSensorNames, sensor), points,
              survey.driven_distance_cm / 100.0, survey.speed_mps, settings.rate_hz, options.out.c_str(), seconds);
  return 0;
}

/// DIR/control.txt (sim/survey_control.hpp) and DIR/control_truth.tum: each scan's true pose in the
/// grid (east, north, height, metres; the scanner's frame turned z up as the map's outputs are).
void write_simulated_control(const SimulateOptions& options, const sim::SimulationSettings& simulation,
                             const sim::SimulatedSurvey& survey) {
  sim::ControlSimulationSettings settings;
  settings.stations = options.control_stations;
  settings.targets = options.control_targets;
  settings.blunder_m = options.control_blunder_m;
  settings.seed = options.seed;
  std::vector<std::string> names;
  for (std::size_t k = 0; k < survey.truth_cm.size(); ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "scan%03zu", k);
    names.emplace_back(name);
  }
  const sim::SimulatedControl control = sim::simulate_control(survey.truth_cm, names, settings, simulation.mine);
  std::vector<std::string> comment{
      "minemap simulate --control " + std::to_string(settings.stations) + " --control-targets " +
          std::to_string(settings.targets) + ": survey stations and targets of the simulated mine",
      "grid: the mine turned " + std::to_string(settings.grid_rotation_deg) + " deg about the vertical, then shifted",
      "sigma " + std::to_string(settings.sigma_horizontal_m) + " m, drawn as noise on every coordinate"};
  if (!control.blunder.empty()) {
    comment.push_back("blunder: " + control.blunder + " is " + std::to_string(settings.blunder_m) + " m off, eastwards");
  }
  io::write_control(options.out / "control.txt", control.file, comment);
  // The truth in the grid as the map's trajectory.tum is written: z up, metres, absolute.
  Eigen::Matrix4d turn = Eigen::Matrix4d::Identity();
  turn.block<3, 3>(0, 0) << 0, 0, 1, -1, 0, 0, 0, 1, 0;  // 3DTK's axes to right-handed, z up
  std::vector<io::TimedPose> truth;
  for (std::size_t k = 0; k < survey.truth_cm.size(); ++k) {
    const Pose in_grid = control.grid_from_mine_cm * survey.truth_cm[k] * turn.transpose();
    truth.push_back({static_cast<double>(k), in_grid});
  }
  io::write_tum(options.out / "control_truth.tum", truth, LengthUnit::kMetre);
}

}  // namespace

CLI::App* add_simulate_command(CLI::App& app, SimulateOptions& options, MapOptions& process) {
  auto* command = app.add_subcommand(
      "simulate", "Write the built-in simulated mine survey (uos format; PCD sweeps for a moving LiDAR)");
  command->add_option("--threads", process.threads, "Worker threads (0 = all cores)")->group(groups::kRun);
  const sim::MineSettings mine;
  command->add_option("--out", options.out, "Output folder")->required();
  char drive[160];
  std::snprintf(drive, sizeof drive,
                "Number of scans (0 = the whole %g m drive); for a moving sensor the number of sweeps (0 = the whole "
                "path)",
                mine.drive_length_cm / 100.0);
  command->add_option("--scans", options.scans, drive);
  command->add_option("--seed", options.seed, "Random seed")->capture_default_str();
  command->add_option("--loop", options.loop_m,
                      "Drive a loop of about this many metres around the pillars right of the drive, back to the "
                      "first scan's place, instead of the straight drive (0 = straight); --scans more than one lap drives round "
                      "again")
      ->check(CLI::NonNegativeNumber);
  CLI::Option* step = command
                          ->add_option("--step-m", options.step_m,
                                       "Mean distance between scan positions (metres): 4 for stop-and-go as the "
                                       "paper, under 1 for a survey where most scans see each other (tilting only)")
                          ->capture_default_str()
                          ->check(CLI::PositiveNumber);
  command->final_callback([step, &options] { options.step_given = step->count() > 0; });

  // The moving LiDARs: PCD sweeps with per-point times, truth.tum, optionally odometry.tum.
  std::vector<std::string> sensors{kTilting};
  for (const std::string& name : names_in(sim::kMovingSensorNames)) sensors.push_back(name);
  const sim::MovingSimulationSettings moving;
  command
      ->add_option("--sensor", options.sensor,
                   "tilting: the paper's 2D scanner tilting at each stop (uos); spinning: a 32-beam spinning LiDAR on "
                   "a vehicle, handheld: a forward-looking rosette LiDAR carried by a walker; both scan while they "
                   "move and write DIR/scanNNN.pcd (metres, the sensor's frame, per-point times) and DIR/truth.tum")
      ->check(CLI::IsMember(sensors))
      ->capture_default_str();
  char help[160];
  std::snprintf(help, sizeof help, "Moving sensors: speed along the path, m/s (default %g spinning, %g handheld)",
                moving.spinning.speed_mps, moving.handheld.speed_mps);
  command->add_option_function<double>("--speed-mps", [&options](double v) { options.speed_mps = v; }, help)
      ->check(CLI::NonNegativeNumber);
  std::snprintf(help, sizeof help, "Moving sensors: sweeps per second (default %g)", moving.rate_hz);
  command->add_option_function<double>("--rate-hz", [&options](double v) { options.rate_hz = v; }, help)
      ->check(CLI::PositiveNumber);
  std::snprintf(help, sizeof help, "Spinning sensor: beams (rings) over %g..%g deg of elevation (default %d)",
                moving.spinning.min_elevation_deg, moving.spinning.max_elevation_deg, moving.spinning.beams);
  command->add_option_function<int>("--beams", [&options](int v) { options.beams = v; }, help)
      ->check(CLI::Range(1, 65535));
  command->add_option_function<double>(
      "--turn-deg-s", [&options](double v) { options.turn_deg_s = v; },
      "Moving sensors: peak rate of an extra yaw weave on top of the path's heading (deg/s; default 0)");
  command->add_option("--control", options.control_stations,
                      "Tilting: write DIR/control.txt, survey stations under this many scan positions (3 or more, "
                      "evenly along the drive) in a mine grid turned and shifted like a UTM one, measured to 5 mm; "
                      "and DIR/control_truth.tum, the true poses in that grid (README, \"Survey control\")")
      ->check(CLI::NonNegativeNumber);
  command->add_option("--control-targets", options.control_targets,
                      "Tilting: also (or only) this many targets on the ribs (right and left in turn), each picked in one scan "
                      "(its x y z in that scan's frame, 5 mm of noise) and known in the grid")
      ->check(CLI::NonNegativeNumber);
  command->add_option("--control-blunder-m", options.control_blunder_m,
                      "Tilting, with --control: the middle station's coordinates this many metres off (a blunder)")
      ->check(CLI::NonNegativeNumber);
  command->add_flag("--odometry", options.odometry,
                    "Moving sensors: the scans carry drifting odometry (PCD VIEWPOINT, and DIR/odometry.tum); "
                    "default none (identity)");
  return command;
}

int run_simulate(const SimulateOptions& options) {
  const int control_points = options.control_stations + options.control_targets;
  if (control_points > 0 && control_points < 3) {
    throw std::invalid_argument("--control and --control-targets: 3 points at least in all (a tie needs 3 not in a line)");
  }
  if (options.control_blunder_m > 0.0 && options.control_stations == 0) {
    throw std::invalid_argument("--control-blunder-m plants a blunder among --control's stations: give --control N");
  }
  if (options.sensor != kTilting) {
    if (control_points > 0) throw std::invalid_argument("--control and --control-targets are the tilting scanner's survey's");
    return run_moving_simulate(options, parse_named(sim::kMovingSensorNames, options.sensor, "sensor"));
  }
  if (options.speed_mps || options.rate_hz || options.beams || options.turn_deg_s || options.odometry) {
    throw std::invalid_argument(
        "--speed-mps, --rate-hz, --beams, --turn-deg-s and --odometry are for a moving sensor "
        "(--sensor spinning or handheld); the tilting scanner stops to scan and always has odometry");
  }
  sim::SimulationSettings settings;
  settings.mine.scans = options.scans;
  settings.mine.seed = options.seed;
  settings.mine.loop_length_cm = 100.0 * options.loop_m;
  settings.mine.mean_step_cm = 100.0 * options.step_m;
  const auto start = std::chrono::steady_clock::now();
  // A part at a time (8 scans a thread, simulated in parallel, then written): a survey of any length
  // in the memory of one part. The folder is checked for the whole survey's count before the first.
  std::size_t points = 0, scans = 0;
  bool prepared = false;
  const std::size_t part_scans = 8 * static_cast<std::size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  const sim::SimulatedSurvey survey =
      sim::simulate_mine_survey_in_parts(settings, part_scans, [&](std::vector<Scan>& part, std::size_t first, std::size_t total) {
        if (!prepared) {
          io::prepare_uos_folder(options.out, total, true);
          prepared = true;
        }
        io::write_uos_scans(options.out, first, part);
        for (const Scan& scan : part) points += scan.size();
        scans += part.size();
      });
  io::write_uos_truth(options.out, survey.truth_cm);
  if (options.control_stations > 0 || options.control_targets > 0) write_simulated_control(options, settings, survey);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("simulated %zu scans (%zu points, %.1f m driven) into %s in %.1f s\n", scans, points,
              survey.driven_distance_cm / 100.0, options.out.c_str(), seconds);
  return 0;
}

}  // namespace minemap::cli
