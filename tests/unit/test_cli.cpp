// The `minemap` program's contract: outputs, exit codes, and messages that name file and line.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <sstream>
#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "test_support.hpp"

namespace minemap {
namespace {

using test::run_cli;
using test::TempDir;
using test::lines_containing;

TEST(Cli, SimulateThenMapWritesEveryOutputAndReportsTruthErrors) {
  TempDir dir;
  std::string output;
  ASSERT_EQ(run_cli("simulate --out " + (dir / "survey").string() + " --scans 3", &output), 0) << output;
  ASSERT_EQ(run_cli("map " + (dir / "survey").string() + " --out " + (dir / "out").string() + " --backend cpu", &output), 0)
      << output;
  EXPECT_NE(output.find("pose error against the reference poses"), std::string::npos) << output;
  for (const char* name :
       {"scan000.frames", "scan002.pose", "trajectory.tum", "map.ply", "report.json", "top.png", "side.png", "map.html"}) {
    EXPECT_TRUE(std::filesystem::exists(dir / "out" / name)) << name;
  }
  std::ifstream in(dir / "out" / "report.json");
  const auto report = nlohmann::json::parse(in);
  ASSERT_EQ(report["scans"].size(), 3u);
  for (const auto& scan : report["scans"]) {
    for (const char* key : {"name", "pose", "iterations", "pairs", "rms", "converged"}) EXPECT_TRUE(scan.contains(key)) << key;
    EXPECT_EQ(scan["pose"].size(), 4u);
  }
  EXPECT_TRUE(report.contains("truth"));
  EXPECT_TRUE(report["timings_s"].contains("relaxation"));
  // No temp file is left behind.
  for (const auto& entry : std::filesystem::directory_iterator(dir / "out")) {
    EXPECT_EQ(entry.path().filename().string().find(".minemap-tmp-"), std::string::npos) << entry.path();
  }
}

// `minemap --version` names the code, and report.json records the run: the version, the command
// line as given, every option that decides the poses (settings) and the rest (run_options), so a
// map can be reproduced from its folder alone.
TEST(Cli, VersionAndAReportThatRecordsTheRun) {
  TempDir dir;
  std::string output;
  ASSERT_EQ(run_cli("--version", &output), 0) << output;
  ASSERT_EQ(output.rfind("minemap ", 0), 0u) << output;
  const std::string version = output.substr(8, output.find('\n') - 8);
  EXPECT_FALSE(version.empty());
  const std::string survey = (dir / "survey").string(), out = (dir / "out").string();
  ASSERT_EQ(run_cli("simulate --out " + survey + " --scans 2", &output), 0) << output;
  ASSERT_EQ(run_cli("map " + survey + " --out " + out + " --backend cpu --voxel-cm 16 --quiet", &output), 0) << output;
  std::ifstream in(dir / "out" / "report.json");
  const auto report = nlohmann::json::parse(in);
  EXPECT_EQ(report["version"], version);
  const std::vector<std::string> line = {"minemap", "map", survey, "--out", out, "--backend", "cpu", "--voxel-cm", "16",
                                         "--quiet"};
  EXPECT_EQ(report["command_line"].get<std::vector<std::string>>(), line);
  EXPECT_EQ(report["settings"]["voxel_cm"], 16);
  EXPECT_EQ(report["settings"]["max_pair_dist_cm"], 25);
  EXPECT_EQ(report["settings"]["retry_bound_factors"], nlohmann::json::array({4, 16}));
  EXPECT_EQ(report["settings"]["mode"], "incremental");
  EXPECT_EQ(report["settings"]["no_filter"], false);
  EXPECT_FALSE(report["settings"].contains("threads"));
  EXPECT_EQ(report["run_options"]["backend"], "cpu");
  EXPECT_EQ(report["run_options"]["quiet"], true);
  EXPECT_GT(report["settings"].size(), 50u);
}

// `simulate --loop` writes a survey that returns to its start; `map` closes the loop, says so, and
// reports it; --no-loop-closing leaves it open.
TEST(Cli, ALoopSurveyIsClosedAndReported) {
  TempDir dir;
  std::string output;
  const std::string survey = (dir / "loop").string();
  ASSERT_EQ(run_cli("simulate --out " + survey + " --loop 80", &output), 0) << output;
  ASSERT_EQ(run_cli("map " + survey + " --out " + (dir / "out").string() + " --backend cpu", &output), 0) << output;
  EXPECT_FALSE(lines_containing(output, "loop closed:").empty()) << output;
  std::ifstream in(dir / "out" / "report.json");
  const auto report = nlohmann::json::parse(in);
  ASSERT_FALSE(report["loop_closures"].empty());
  bool closed = false;
  for (const auto& loop : report["loop_closures"]) closed = closed || loop["closed"].get<bool>();
  EXPECT_TRUE(closed);
  EXPECT_TRUE(report["doubtful_scans"].empty());
  ASSERT_EQ(run_cli("map " + survey + " --out " + (dir / "open").string() + " --backend cpu --no-loop-closing", &output),
            0)
      << output;
  EXPECT_TRUE(lines_containing(output, "loop closed:").empty()) << output;
}

// uos files without "# slice" markers (as other tools write them): the slices are found from the
// scanner order, the run says so, and the slice filter applies as it does with markers.
TEST(Cli, UnmarkedUosFilesGetTheirSlicesFromTheScannerOrder) {
  TempDir dir;
  std::string output;
  const auto survey = dir / "survey";
  ASSERT_EQ(run_cli("simulate --out " + survey.string() + " --scans 3", &output), 0) << output;
  for (const char* name : {"scan000.3d", "scan001.3d", "scan002.3d"}) {
    std::istringstream in(test::read_text(survey / name));
    std::string line, kept;
    while (std::getline(in, line)) {
      if (line.rfind("# slice", 0) != 0) kept += line + "\n";
    }
    test::write_text(survey / name, kept);
  }
  const std::string map = "map " + survey.string() + " --backend cpu --preset simultaneous --out ";
  ASSERT_EQ(run_cli(map + (dir / "found").string(), &output), 0) << output;
  EXPECT_EQ(lines_containing(output, "3 of 3 uos files have no '# slice' markers").size(), 1u) << output;
  std::ifstream in(dir / "found" / "report.json");
  const auto report = nlohmann::json::parse(in);
  EXPECT_TRUE(report["notes"].empty()) << report["notes"];  // no "slice filter skipped"
  ASSERT_EQ(report["timings_s"]["per_scan"].size(), 3u);
  EXPECT_GT(report["timings_s"]["per_scan"][2].get<double>(), 0.0);
  ASSERT_EQ(run_cli(map + (dir / "without").string() + " --no-slice-detection", &output), 0) << output;
  EXPECT_TRUE(lines_containing(output, "uos files have no '# slice' markers").empty()) << output;
  std::ifstream without(dir / "without" / "report.json");
  EXPECT_FALSE(nlohmann::json::parse(without)["notes"].empty());
}

// Survey control (issue 29): the simulator's stations, one of them planted 0.5 m wrong; the map is in
// the grid (trajectory.tum plus report.json's origin is the truth the simulator wrote), the blunder
// is named and the run exits 13; the export is in grid coordinates; a control file naming a scan the
// survey lacks is refused by file and line before anything is mapped or written.
TEST(Cli, AMapTiedToControlIsInTheGridAndNamesABlunder) {
  TempDir dir;
  std::string output;
  const std::string survey = (dir / "survey").string();
  ASSERT_EQ(run_cli("simulate --out " + survey + " --scans 24 --control 4 --control-blunder-m 0.5", &output), 0)
      << output;
  const std::string control = (dir / "survey" / "control.txt").string();
  EXPECT_EQ(run_cli("map " + survey + " --out " + (dir / "out").string() + " --backend cpu --control " + control,
                    &output),
            13)
      << output;
  EXPECT_NE(output.find("blunder: left out"), std::string::npos) << output;
  EXPECT_NE(output.find("control point S3 lies"), std::string::npos) << output;
  std::ifstream in(dir / "out" / "report.json");
  const auto report = nlohmann::json::parse(in);
  ASSERT_TRUE(report.contains("control"));
  EXPECT_EQ(report["control"]["points_used"], 3);
  EXPECT_EQ(report["control"]["epsg"], 32633);
  for (const auto& r : report["control"]["residuals"]) EXPECT_EQ(r["blunder"].get<bool>(), r["point"] == "S3") << r;
  EXPECT_TRUE(report["scans"][5].contains("sigma"));
  const auto origin = report["control"]["origin_grid_m"].get<std::vector<double>>();
  const auto first_line = [](const std::filesystem::path& path) {
    std::ifstream file(path);
    std::string line;
    while (std::getline(file, line) && line.front() == '#') {}
    std::istringstream values(line);
    double t, x, y, z;
    values >> t >> x >> y >> z;
    return Eigen::Vector3d(x, y, z);
  };
  const Eigen::Vector3d mapped = first_line(dir / "out" / "trajectory.tum") + Eigen::Vector3d(origin[0], origin[1], origin[2]);
  const Eigen::Vector3d truth = first_line(dir / "survey" / "control_truth.tum");
  EXPECT_GT(truth.y(), 7e6);  // a UTM-size northing
  EXPECT_LT((mapped - truth).norm(), 0.05) << mapped.transpose() << " / " << truth.transpose();
  EXPECT_NE(test::read_text(dir / "out" / "map.ply").find("grid: add the origin"), std::string::npos);
  ASSERT_EQ(run_cli("export " + (dir / "out").string() + " --to " + (dir / "grid.ply").string(), &output), 0) << output;
  EXPECT_TRUE(std::filesystem::exists(dir / "grid.ply"));

  test::write_text(dir / "bad.txt", "point S1 1 2 3 0.01\npoint S2 4 5 6 0.01\nstation scan999 S1\n");
  EXPECT_EQ(run_cli("map " + survey + " --out " + (dir / "never").string() + " --control " + (dir / "bad.txt").string(),
                    &output),
            10)
      << output;
  EXPECT_NE(output.find("bad.txt:3:"), std::string::npos) << output;
  EXPECT_FALSE(std::filesystem::exists(dir / "never"));
  // watch maps scans as they arrive: it refuses the tie rather than ignore it.
  EXPECT_EQ(run_cli("watch " + survey + " --out " + (dir / "live").string() + " --control " + control, &output), 2)
      << output;
  EXPECT_NE(output.find("--control ties a finished survey"), std::string::npos) << output;
}

TEST(Cli, BadInputNamesFileAndLineAndLeavesTheOutputFolderAsItWas) {
  TempDir dir;
  std::filesystem::create_directories(dir / "survey");
  test::write_text(dir / "survey" / "scan000.3d", "1 2 3\n4 5 6\n");
  test::write_text(dir / "survey" / "scan000.pose", "0 0 0\n0 0 0\n");
  test::write_text(dir / "survey" / "scan001.3d", "1 2 3\n4 five 6\n");
  test::write_text(dir / "survey" / "scan001.pose", "0 0 0\n0 0 0\n");
  std::filesystem::create_directories(dir / "out");
  test::write_text(dir / "out" / "keep.txt", "previous result");
  std::string output;
  const int code = run_cli("map " + (dir / "survey").string() + " --out " + (dir / "out").string(), &output);
  EXPECT_EQ(code, 3) << output;
  EXPECT_NE(output.find("scan001.3d:2:"), std::string::npos) << output;
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir / "out")) names.push_back(entry.path().filename());
  EXPECT_EQ(names, std::vector<std::string>{"keep.txt"});
  EXPECT_EQ(test::read_text(dir / "out" / "keep.txt"), "previous result");
}

TEST(Cli, ADoubtfulRegistrationIsNamedWrittenAndExits13UnlessAccepted) {
  // The LiDAR pair from the identity: 0.5 m apart, twice the default 25 cm bound's reach (the
  // retry from a wider bound, which would make it right, is switched off, and so is the recovery
  // that would confirm it from the scan's features; the start is the odometry's: the
  // constant-velocity model's first match would start at 2 m).
  TempDir dir;
  const std::string survey = (test::shared_data_dir() / "fast_gicp_pair").string();
  std::string output;
  ASSERT_EQ(run_cli("map " + survey + " --out " + (dir / "out").string() + " --backend cpu --quiet --no-retry --no-recovery --motion-model odometry", &output),
            13)
      << output;
  const auto named = lines_containing(output, "scan 251371071 registered, but doubtful: the match moved its points");
  EXPECT_EQ(named.size(), 1u) << output;
  EXPECT_EQ(lines_containing(output, "1 of 2 scans doubtful").size(), 1u) << output;
  std::ifstream in(dir / "out" / "report.json");
  const auto report = nlohmann::json::parse(in);
  EXPECT_EQ(report["doubtful_scans"], nlohmann::json::array({"251371071"}));
  EXPECT_FALSE(report["scans"][1]["health"]["trusted"].get<bool>());
  EXPECT_EQ(run_cli("map " + survey + " --out " + (dir / "accepted").string() +
                        " --backend cpu --quiet --no-retry --no-recovery --motion-model odometry --accept-doubtful",
                    &output), 0) << output;
  EXPECT_EQ(run_cli("map " + survey + " --out " + (dir / "wide").string() + " --backend cpu --quiet --max-pair-dist-cm 100",
                    &output), 0) << output;
  EXPECT_EQ(run_cli("map " + survey + " --out " + (dir / "retried").string() + " --backend cpu --quiet", &output), 0)
      << output;
}

TEST(Cli, ALoggedRunPrintsTheScanOrderAndAProgressLinePerScan) {
  TempDir dir;
  std::string output;
  ASSERT_EQ(run_cli("simulate --out " + (dir / "survey").string() + " --scans 3", &output), 0) << output;
  // run_cli captures stderr into a file: not a terminal, so plain lines instead of a bar.
  ASSERT_EQ(run_cli("map " + (dir / "survey").string() + " --out " + (dir / "out").string() + " --backend cpu", &output), 0)
      << output;
  EXPECT_EQ(lines_containing(output, "scan order: scan000, scan001, scan002").size(), 1u) << output;
  // Read and reduced a part at a time as it is matched: the progress is the matching's.
  EXPECT_EQ(lines_containing(output, "minemap: progress: incremental 2/3").size(), 1u) << output;
  EXPECT_EQ(lines_containing(output, "minemap: progress: incremental 3/3").size(), 1u) << output;
  EXPECT_TRUE(lines_containing(output, "\r").empty()) << output;
}

TEST(Cli, ReferencePosesGiveAnyRealSurveyItsErrorReport) {
  TempDir dir;
  const auto data = test::shared_data_dir() / "fast_gicp_pair";
  // scan 251370668 at the identity, 251371071 where the pair's own relative.txt puts it.
  test::write_text(dir / "reference.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n" + test::read_text(data / "relative.txt"));
  std::string output;
  ASSERT_EQ(run_cli("map " + data.string() + " --out " + (dir / "out").string() +
                        " --backend cpu --max-pair-dist-cm 100 --reference-poses " + (dir / "reference.txt").string(),
                    &output),
            0)
      << output;
  const auto lines = lines_containing(output, "  registered mean ");
  ASSERT_EQ(lines.size(), 1u) << output;
  // The point-to-point minimum lies about 1 cm from relative.txt (a GICP result; docs/benchmarks.md).
  const double mean_m = std::stod(lines[0].substr(lines[0].find("mean ") + 5));
  EXPECT_LT(mean_m, 0.02) << lines[0];
}

TEST(Cli, UsageAndBackendErrorsHaveTheirOwnExitCodes) {
  TempDir dir;
  std::string output;
  EXPECT_EQ(run_cli("map", &output), 2) << output;
  EXPECT_EQ(run_cli("map " + dir.path().string() + " --out " + (dir / "o").string() + " --mode sideways", &output), 2)
      << output;
  ASSERT_EQ(run_cli("simulate --out " + (dir / "s").string() + " --scans 2", &output), 0) << output;
  EXPECT_EQ(run_cli("--opencl-device no-such-device map " + (dir / "s").string() + " --out " + (dir / "o").string() +
                        " --backend opencl --quiet",
                    &output),
            6)
      << output;
  EXPECT_NE(output.find("no-such-device"), std::string::npos) << output;
}

// --threads and --opencl-device work where users type them, before or after the subcommand, and
// each subcommand's --help lists them (the README lists them among `map`'s options).
TEST(Cli, ProcessOptionsWorkAfterTheSubcommandAndAreInItsHelp) {
  TempDir dir;
  std::string output;
  ASSERT_EQ(run_cli("simulate --out " + (dir / "s").string() + " --scans 2 --threads 1", &output), 0) << output;
  EXPECT_EQ(run_cli("map " + (dir / "s").string() + " --out " + (dir / "o").string() + " --threads 1 --quiet", &output),
            0)
      << output;
  EXPECT_EQ(run_cli("map " + (dir / "s").string() + " --out " + (dir / "o2").string() +
                        " --opencl-device no-such-device --backend opencl --quiet",
                    &output),
            6)
      << output;
  EXPECT_NE(output.find("no-such-device"), std::string::npos) << output;
  for (const std::string command : {"map", "simulate"}) {
    ASSERT_EQ(run_cli(command + " --help", &output), 0) << output;
    EXPECT_NE(output.find("--threads"), std::string::npos) << command << ":\n" << output;
  }
  ASSERT_EQ(run_cli("map --help", &output), 0) << output;
  EXPECT_NE(output.find("--opencl-device"), std::string::npos) << output;
}

TEST(Cli, SigintStopsMappingWithExit130AndNoTempFiles) {
  TempDir dir;
  std::string output;
  ASSERT_EQ(run_cli("simulate --out " + (dir / "s").string() + " --scans 20", &output), 0) << output;
  // Brute-force pairing makes the run long (about 15 s here, 20 scans x 5 iterations), so the
  // signal lands mid-run even on a machine ten times faster.
  // Not quiet, stderr to a file: a progress line per matched scan (log mode), which shows how many
  // scans were matched after the signal.
  const auto log = dir / "progress.log";
  const std::string command = std::string(MINEMAP_CLI_PATH) + " map " + (dir / "s").string() + " --out " +
                              (dir / "o").string() + " --backend cpu --mode pairwise --search brute" +
                              " --max-iterations 5 > /dev/null 2> " + log.string();
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::execl("/bin/sh", "sh", "-c", ("exec " + command).c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  // Signal once matching has begun (a progress line of the pairwise mode is in the log).
  const auto matched = [&] { return lines_containing(test::read_text(log), "progress: pairwise").size(); };
  for (int waited = 0; matched() == 0 && waited < 600; ++waited) ::usleep(100 * 1000);
  const std::size_t before = matched();
  ASSERT_GT(before, 0u) << test::read_text(log);
  ::kill(child, SIGINT);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);
  // It stops after the scan it was matching (one more progress line; two, had one just ended as the
  // log was read), however long that took on a loaded machine.
  EXPECT_LE(matched(), before + 2) << test::read_text(log);
  ASSERT_TRUE(std::filesystem::exists(dir / "o"));
  for (const auto& entry : std::filesystem::directory_iterator(dir / "o")) {
    EXPECT_EQ(entry.path().filename().string().find(".minemap-tmp-"), std::string::npos) << entry.path();
  }
  // What was matched is kept: the outputs of the scans matched so far, marked partial.
  std::ifstream in(dir / "o" / "report.json");
  const auto report = nlohmann::json::parse(in);
  EXPECT_TRUE(report["partial"].get<bool>());
  EXPECT_EQ(report["scans_in_survey"].get<int>(), 20);
  const std::size_t kept = report["scans"].size();
  EXPECT_GE(kept, 1u);
  EXPECT_LT(kept, 20u);
  EXPECT_TRUE(std::filesystem::exists(dir / "o" / "scan000.pose"));
  char first_missing[32];
  std::snprintf(first_missing, sizeof first_missing, "scan%03zu.pose", kept);
  EXPECT_FALSE(std::filesystem::exists(dir / "o" / first_missing));
}


// `watch` on a folder whose scans are all there already: it matches them one by one, finishes at
// --scans, and writes what `map` of the folder writes (report.json's times aside); a second watch
// with more scans resumes from watch.json without matching the first ones again. (The scans
// arriving one by one, Ctrl-C and order are python/tests/test_watch.py's.)
TEST(Cli, WatchEndsAsMapOfTheSameFolderAndResumes) {
  TempDir dir("minemap-cli-watch");
  std::string output;
  const std::string survey = (dir / "survey").string();
  ASSERT_EQ(run_cli("simulate --out " + survey + " --scans 4", &output), 0) << output;
  ASSERT_EQ(run_cli("map " + survey + " --out " + (dir / "map").string() + " --backend cpu --quiet", &output), 0)
      << output;
  const std::string live = (dir / "live").string();
  ASSERT_EQ(run_cli("watch " + survey + " --out " + live + " --backend cpu --scans 2", &output), 0) << output;
  EXPECT_NE(output.find("scan001: read"), std::string::npos) << output;
  EXPECT_NE(output.find("(2 scans)"), std::string::npos) << output;
  EXPECT_EQ(output.find("(1 scans)"), std::string::npos) << output;
  // Resuming with another setting names it, on one line.
  EXPECT_EQ(run_cli("watch " + survey + " --out " + live + " --backend cpu --scans 4 --voxel-cm 20", &output), 10)
      << output;
  EXPECT_NE(output.find("other mapping options (--voxel-cm: saved (default), given 20)"), std::string::npos)
      << output;
  ASSERT_EQ(run_cli("watch " + survey + " --out " + live + " --backend cpu --scans 4", &output), 0) << output;
  EXPECT_NE(output.find("2 scans matched before"), std::string::npos) << output;
  EXPECT_EQ(output.find("scan001: read"), std::string::npos) << output;
  for (const auto& entry : std::filesystem::directory_iterator(dir / "map")) {
    const std::string name = entry.path().filename().string();
    if (name == "minemap.log") continue;  // the run's console output: its command, times and paths
    if (name == "report.json") {
      auto a = nlohmann::json::parse(test::read_text(entry.path()));
      auto b = nlohmann::json::parse(test::read_text(dir / "live" / name));
      for (const char* key : {"timings_s", "memory_mb", "command_line", "run_options"}) {  // how each run was asked for
        a.erase(key);
        b.erase(key);
      }
      EXPECT_EQ(a, b);
    } else {
      EXPECT_TRUE(test::read_text(entry.path()) == test::read_text(dir / "live" / name)) << name;
    }
  }
}

// KITTI 07 read with no poses: the car's 3-12 m steps start out of the motion model's reach, the
// matches end right, and a second match from each scan's FPFH features agrees: exit 0, every scan
// trusted, the summary and report.json say which were recovered or confirmed. --no-recovery gives
// the old verdicts (exit 13).
TEST(Cli, ScansOutOfReachAreRecoveredOrConfirmedAndSaySo) {
  TempDir dir;
  const std::string survey = (test::shared_data_dir() / "kitti07_sequence").string();
  std::string output;
  ASSERT_EQ(run_cli("map " + survey + " --out " + (dir / "out").string() + " --backend cpu --threads 2", &output), 0)
      << output;
  std::ifstream in(dir / "out" / "report.json");
  const auto report = nlohmann::json::parse(in);
  EXPECT_TRUE(report["doubtful_scans"].empty());
  std::size_t said = 0;
  for (const auto& scan : report["scans"]) {
    if (!scan.contains("health")) continue;
    const auto& health = scan["health"];
    EXPECT_TRUE(health["trusted"].get<bool>()) << scan["name"];
    said += health["recovered"].get<bool>() || health["note"].get<std::string>().find("FPFH") != std::string::npos;
  }
  EXPECT_GE(said, 1u) << output;
  EXPECT_EQ(run_cli("map " + survey + " --out " + (dir / "off").string() + " --backend cpu --threads 2 --quiet --no-recovery",
                    &output),
            13)
      << output;
}

// KITTI has reference poses (graph.txt) and no odometry: the error row of the starts is not called
// odometry.
TEST(Cli, IdentityStartsAreNotCalledOdometry) {
  TempDir dir("minemap-cli-kitti");
  std::string output;
  // --no-recovery: the wording is the subject, not the FPFH registrations (40 % of the run).
  run_cli("map " + (test::shared_data_dir() / "kitti07_sequence").string() + " --out " + (dir / "out").string() +
              " --backend cpu --accept-doubtful --no-recovery",
          &output);
  EXPECT_NE(output.find("  start      mean"), std::string::npos) << output;
  EXPECT_NE(output.find("every scan at the identity, the survey has no odometry"), std::string::npos) << output;
  EXPECT_EQ(output.find("  odometry   mean"), std::string::npos) << output;
}

// A pair's relative transform, as fast_gicp, Open3D and PCL write one, is a pair's reference poses:
// the same errors as the two-pose file {identity, T}.
TEST(Cli, APairsRelativeTransformIsItsReferencePoses) {
  TempDir dir("minemap-cli-relative");
  const auto data = test::shared_data_dir() / "fast_gicp_pair";
  test::write_text(dir / "two.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n" + test::read_text(data / "relative.txt"));
  std::string output;
  for (const char* name : {"relative", "two"}) {
    const std::string poses = std::string(name) == "relative" ? (data / "relative.txt").string() : (dir / "two.txt").string();
    ASSERT_EQ(run_cli("map " + data.string() + " --out " + (dir / name).string() + " --backend cpu --quiet " +
                          "--reference-poses " + poses,
                      &output),
              0)
        << output;
  }
  const auto truth = [&](const char* name) {
    return nlohmann::json::parse(test::read_text(dir / name / "report.json"))["truth"];
  };
  ASSERT_FALSE(truth("relative").is_null());
  EXPECT_EQ(truth("relative"), truth("two"));
}

// The verdict must not flip on the same pose: Jinchuan's second segment is trusted at the default
// (after the 4 m retry) and was doubtful at the README's own --max-pair-dist-cm 200 ("moved its
// points 544 cm, 2.7 times the bound": the 8 m rung was beyond the widest retry, so none ran).
TEST(Cli, AWideBoundOfTheUsersOwnIsRetriedAsTheDefaultIs) {
  TempDir dir("minemap-cli-jinchuan");
  const auto data = test::shared_data_dir() / "mine_jinchuan_pcr";
  std::string output;
  ASSERT_EQ(run_cli("map " + data.string() + " --out " + (dir / "default").string() + " --backend cpu --quiet", &output),
            0)
      << output;
  ASSERT_EQ(run_cli("map " + data.string() + " --out " + (dir / "wide").string() +
                        " --backend cpu --quiet --max-pair-dist-cm 200",
                    &output),
            0)
      << output;
  const auto second = [&](const char* name) {
    return nlohmann::json::parse(test::read_text(dir / name / "report.json"))["scans"][1];
  };
  EXPECT_EQ(second("wide")["health"]["retry_bound"], 4.0);
  Pose a, b;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      a(r, c) = second("default")["pose"][r][c].get<double>();
      b(r, c) = second("wide")["pose"][r][c].get<double>();
    }
  }
  EXPECT_LT((a.block<3, 1>(0, 3) - b.block<3, 1>(0, 3)).norm(), 0.02) << "metres";
  EXPECT_LT(rotation_angle_deg(rigid_inverse(a) * b), 0.2);
}

}  // namespace
}  // namespace minemap
