// Survey folders: the uos round trip (points, slices, poses, truth), layout detection, initial pose
// files, and the errors for missing poses, empty or mixed folders and pose-count mismatches.
#include <gtest/gtest.h>

#include "io_test_helpers.hpp"
#include "minemap/io/formats.hpp"

namespace minemap {
namespace {

using test::expect_input_error;
using test::TempDir;
using test::write_text;

std::vector<Scan> sample_scans(std::size_t count) {
  std::vector<Scan> scans;
  for (std::size_t k = 0; k < count; ++k) {
    Scan scan = test::random_scan(300 + 50 * k, -2000.0f, 2000.0f, static_cast<std::uint32_t>(100 + k));
    scan.slice_offsets = {0, 100, 200, static_cast<std::uint32_t>(scan.size())};
    EulerPose euler;
    euler.position_cm = Eigen::Vector3d(500.0 * static_cast<double>(k), 10.0, -3.25);
    euler.angles_deg = Eigen::Vector3d(1.0, 15.0 * static_cast<double>(k), -2.0);
    scan.pose_cm = euler_to_pose(euler);
    scans.push_back(std::move(scan));
  }
  return scans;
}

TEST(Survey, UosRoundTripKeepsPointsSlicesPosesAndTruth) {
  TempDir dir;
  const auto scans = sample_scans(3);
  std::vector<Pose> truth;
  for (const Scan& scan : scans) truth.push_back(scan.pose_cm * euler_to_pose({Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(0, 0, 1)}));
  io::write_uos_survey(dir.path(), scans, truth);
  EXPECT_TRUE(std::filesystem::exists(dir / "scan002.3d"));
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "truth" / "scan002.pose"));

  const io::Survey survey = io::read_survey(dir.path());
  EXPECT_EQ(survey.format, "uos");
  EXPECT_EQ(survey.unit, LengthUnit::kCentimetre);
  ASSERT_EQ(survey.scans.size(), scans.size());
  ASSERT_TRUE(survey.truth_cm.has_value());
  for (std::size_t k = 0; k < scans.size(); ++k) {
    const Scan& back = survey.scans[k];
    EXPECT_EQ(back.name, "scan00" + std::to_string(k));
    EXPECT_EQ(back.points_cm, scans[k].points_cm);
    EXPECT_EQ(back.slice_offsets, scans[k].slice_offsets);
    EXPECT_LT((back.pose_cm - scans[k].pose_cm).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_LT(((*survey.truth_cm)[k] - truth[k]).cwiseAbs().maxCoeff(), 1e-9);
  }
  // Without truth/ there is no truth.
  std::filesystem::remove_all(dir.path() / "truth");
  EXPECT_FALSE(io::read_survey(dir.path()).truth_cm.has_value());
}

// A long survey is read a part at a time (`map` on the CPU): each part is the scans read_survey reads
// (poses, the world origin the first scan chose), handed over before the next is parsed, and may be
// freed; what needs every scan (truth, duplicates, units) still holds.
TEST(Survey, ReadInPartsIsReadAllAtOnceAndFreesWhatItHandsOver) {
  TempDir dir;
  auto scans = sample_scans(5);
  std::vector<Pose> truth;
  for (Scan& scan : scans) {
    scan.pose_cm(0, 3) += 3.0e7;  // world coordinates: 300 km east
    truth.push_back(scan.pose_cm * euler_to_pose({Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(0, 0, 1)}));
  }
  io::write_uos_survey(dir.path(), scans, truth);
  const io::Survey whole = io::read_survey(dir.path());
  ASSERT_FALSE(whole.origin_cm.isZero());
  std::vector<std::size_t> firsts;
  const auto freeing = [&](std::vector<Scan>& part, std::size_t first, std::size_t total) {
    EXPECT_EQ(total, 5u);
    firsts.push_back(first);
    for (std::size_t k = 0; k < part.size(); ++k) {
      const Scan& expected = whole.scans[first + k];
      EXPECT_EQ(part[k].name, expected.name);
      EXPECT_EQ(part[k].points_cm, expected.points_cm);
      EXPECT_EQ(part[k].local_origin_cm, expected.local_origin_cm);
      EXPECT_EQ(part[k].pose_cm, expected.pose_cm);
      std::vector<Eigen::Vector3f>().swap(part[k].points_cm);
    }
    return true;
  };
  const io::Survey parts = io::read_survey_in_parts(dir.path(), {}, 2, freeing);
  EXPECT_EQ(firsts, (std::vector<std::size_t>{0, 2, 4}));
  EXPECT_EQ(parts.origin_cm, whole.origin_cm);
  EXPECT_EQ(parts.format, whole.format);
  EXPECT_EQ(parts.warnings, whole.warnings);
  ASSERT_TRUE(parts.truth_cm.has_value());
  EXPECT_EQ(*parts.truth_cm, *whole.truth_cm);
  ASSERT_EQ(parts.scans.size(), 5u);
  for (const Scan& scan : parts.scans) EXPECT_TRUE(scan.points_cm.empty());

  // A copy of scan000 as scan004, in another part: found though both scans' points were freed.
  const auto original = test::read_text(dir / "scan004.3d");
  std::filesystem::copy_file(dir / "scan000.3d", dir / "scan004.3d", std::filesystem::copy_options::overwrite_existing);
  const auto just_freeing = [](std::vector<Scan>& part, std::size_t, std::size_t) {
    for (Scan& scan : part) std::vector<Eigen::Vector3f>().swap(scan.points_cm);
    return true;
  };
  expect_input_error([&] { io::read_survey_in_parts(dir.path(), {}, 2, just_freeing); },
                     {(dir / "scan004.3d").string(), "exactly the same", "scan000.3d"});
  expect_input_error([&] { io::read_survey(dir.path()); }, {(dir / "scan004.3d").string(), "exactly the same"});
  // A broken file in the third part: the parts before it were handed over, then the file is named.
  write_text(dir / "scan004.3d", "1 2 3\nbroken line\n");
  std::size_t handed = 0;
  const auto counting = [&](std::vector<Scan>& part, std::size_t, std::size_t) {
    handed += part.size();
    return true;
  };
  expect_input_error([&] { io::read_survey_in_parts(dir.path(), {}, 2, counting); },
                     {(dir / "scan004.3d").string() + ":2:"});
  EXPECT_EQ(handed, 4u);
  // A consumer that stops (an interrupted run): no further part is read, nothing checked as a whole.
  write_text(dir / "scan004.3d", original);
  handed = 0;
  const io::Survey stopped = io::read_survey_in_parts(
      dir.path(), {}, 2, [&](std::vector<Scan>& part, std::size_t, std::size_t) { return (handed += part.size()) < 2; });
  EXPECT_EQ(handed, 2u);
  EXPECT_EQ(stopped.scans.size(), 2u);
  EXPECT_THROW(io::read_survey_in_parts(dir.path(), {}, 0, counting), std::invalid_argument);
}

TEST(Survey, UosNumberingGapsKeepNumberOrder) {
  TempDir dir;
  const auto scans = sample_scans(3);
  const char* stems[] = {"scan010", "scan002", "scan1000"};  // 1000 sorts before 002 as text
  for (std::size_t k = 0; k < 3; ++k) {
    io::write_uos_points(dir / (std::string(stems[k]) + ".3d"), scans[k]);
    io::write_uos_pose(dir / (std::string(stems[k]) + ".pose"), scans[k].pose_cm);
  }
  const io::Survey survey = io::read_survey(dir.path());
  ASSERT_EQ(survey.scans.size(), 3u);
  EXPECT_EQ(survey.scans[0].name, "scan002");
  EXPECT_EQ(survey.scans[1].name, "scan010");
  EXPECT_EQ(survey.scans[2].name, "scan1000");
  EXPECT_EQ(survey.scans[0].size(), scans[1].size());
  // The gaps are a warning naming the missing numbers (docs/bad-input.md), not an error.
  ASSERT_EQ(survey.warnings.size(), 1u);
  EXPECT_NE(survey.warnings[0].find("no scan003..scan009, scan011..scan999"), std::string::npos) << survey.warnings[0];
}

TEST(Survey, UosErrorsNameTheFile) {
  TempDir dir;
  const auto scans = sample_scans(3);
  io::write_uos_survey(dir.path(), scans, std::vector<Pose>(3, Pose::Identity()));
  // A partial truth/ folder is a mistake, not "no truth".
  std::filesystem::remove(dir.path() / "truth" / "scan001.pose");
  expect_input_error([&] { io::read_survey(dir.path()); }, {"truth/scan001.pose", "missing"});
  std::filesystem::remove_all(dir.path() / "truth");
  // A missing pose file names the pose file.
  std::filesystem::remove(dir / "scan001.pose");
  expect_input_error([&] { io::read_survey(dir.path()); }, {(dir / "scan001.pose").string(), "missing"});
  // ... unless initial poses are given, in any trajectory format.
  io::write_tum(dir / "initial.tum", std::vector<io::TimedPose>(3), LengthUnit::kCentimetre);
  io::SurveyReadSettings settings;
  settings.initial_poses = dir / "initial.tum";
  settings.read.unit = LengthUnit::kCentimetre;
  const io::Survey survey = io::read_survey(dir.path(), settings);
  for (const Scan& scan : survey.scans) EXPECT_TRUE(scan.pose_cm.isIdentity());
  // A broken point file is reported with its own name and line.
  write_text(dir / "scan002.3d", "1 2 3\nbroken line\n");
  expect_input_error([&] { io::read_survey(dir.path(), settings); }, {(dir / "scan002.3d").string() + ":2:"});
  // Two files with one number.
  io::write_uos_points(dir / "scan0001.3d", scans[1]);
  expect_input_error([&] { io::read_survey(dir.path(), settings); }, {"same scan number"});
}

TEST(Survey, EmptyMixedAndMissingFoldersAreRefused) {
  TempDir dir;
  expect_input_error([&] { io::read_survey(dir.path()); }, {dir.path().string(), "no scans found"});
  write_text(dir / "notes.txt", "not a scan");
  expect_input_error([&] { io::read_survey(dir.path()); }, {"no scans found"});
  expect_input_error([&] { io::read_survey(dir / "absent"); }, {"absent", "not a folder"});
  const Scan scan = test::random_scan(10, -1.0f, 1.0f, 1);
  io::write_pcd(dir / "a.pcd", scan, io::PcdEncoding::kBinary);
  io::write_uos_points(dir / "scan000.3d", scan);
  expect_input_error([&] { io::read_survey(dir.path()); }, {dir.path().string(), "several layouts"});
}

TEST(Survey, PcdAndPlyFoldersWithInitialPoses) {
  TempDir dir;
  const auto scans = sample_scans(3);
  const char* names[] = {"b_second", "a_first", "c_third"};
  for (std::size_t k = 0; k < 3; ++k) {
    Scan scan = scans[k];
    scan.pose_cm = Pose::Identity();
    io::write_pcd(dir / (std::string(names[k]) + ".pcd"), scan, io::PcdEncoding::kBinaryCompressed);
  }
  io::Survey survey = io::read_survey(dir.path());
  EXPECT_EQ(survey.format, "pcd");
  EXPECT_EQ(survey.unit, LengthUnit::kMetre);
  ASSERT_EQ(survey.scans.size(), 3u);
  EXPECT_EQ(survey.scans[0].name, "a_first");  // sorted by name
  EXPECT_EQ(survey.scans[0].size(), scans[1].size());
  EXPECT_TRUE(survey.scans[0].pose_cm.isIdentity());
  EXPECT_FALSE(survey.truth_cm.has_value());

  TempDir poses_dir;
  std::vector<Pose> initial;
  for (const Scan& scan : scans) initial.push_back(scan.pose_cm);
  io::write_kitti_poses(poses_dir / "initial_kitti.txt", initial);
  io::SurveyReadSettings settings;
  settings.initial_poses = poses_dir / "initial_kitti.txt";
  survey = io::read_survey(dir.path(), settings);
  for (std::size_t k = 0; k < 3; ++k) EXPECT_LT((survey.scans[k].pose_cm - initial[k]).cwiseAbs().maxCoeff(), 1e-9);

  initial.pop_back();
  io::write_matrix_poses(poses_dir / "two.txt", initial);
  settings.initial_poses = poses_dir / "two.txt";
  expect_input_error([&] { io::read_survey(dir.path(), settings); }, {"two.txt", "has 2 poses, the survey has 3 scans"});

  // The files are parsed at once (as uos'); the first broken one in name order is the one named.
  write_text(dir / "c_third.pcd", "VERSION 0.7\nFIELDS x y z\nbroken\n");
  write_text(dir / "b_second.pcd", "VERSION 0.7\nFIELDS x y z\nbroken\n");
  expect_input_error([&] { io::read_survey(dir.path()); }, {(dir / "b_second.pcd").string()});

  TempDir ply_dir;
  io::write_ply(ply_dir / "map.ply", scans[0].points_cm, true, LengthUnit::kMetre);
  survey = io::read_survey(ply_dir.path());
  EXPECT_EQ(survey.format, "ply");
  ASSERT_EQ(survey.scans.size(), 1u);
  EXPECT_EQ(survey.scans[0].name, "map");
}

TEST(Survey, KittiFolderLayouts) {
  TempDir flat;
  const auto scans = sample_scans(2);
  io::write_kitti_bin(flat / "000000.bin", scans[0]);
  io::write_kitti_bin(flat / "000001.bin", scans[1]);
  io::Survey survey = io::read_survey(flat.path());
  EXPECT_EQ(survey.format, "kitti");
  ASSERT_EQ(survey.scans.size(), 2u);
  EXPECT_EQ(survey.scans[1].name, "000001");
  EXPECT_EQ(survey.scans[1].size(), scans[1].size());

  TempDir nested;
  std::vector<Pose> graph;
  for (std::size_t k = 0; k < 2; ++k) {
    const auto folder = nested.path() / ("00000" + std::to_string(k));
    std::filesystem::create_directories(folder);
    io::write_kitti_bin(folder / "points.bin", scans[k], 3);
    graph.push_back(scans[k].pose_cm);
  }
  io::write_graph_poses(nested / "graph.txt", graph);
  survey = io::read_survey(nested.path());
  ASSERT_EQ(survey.scans.size(), 2u);
  EXPECT_EQ(survey.scans[0].name, "000000");
  EXPECT_TRUE(survey.scans[0].pose_cm.isIdentity());  // initial guess: identity
  ASSERT_TRUE(survey.truth_cm.has_value());
  for (std::size_t k = 0; k < 2; ++k) EXPECT_LT(((*survey.truth_cm)[k] - graph[k]).cwiseAbs().maxCoeff(), 1e-9);
  write_text(nested / "graph.txt", "v0 0 0 0 0 0 0 1\n");
  expect_input_error([&] { io::read_survey(nested.path()); }, {"graph.txt", "has 1 poses"});
}

TEST(Survey, ScansAreInNaturalOrderSoPoseLinesPairWithTheRightScans) {
  // Byte order would give full0, full1, full10, full100, full2: the wrong pairing.
  TempDir dir;
  const auto scans = sample_scans(5);
  const char* names[] = {"full10", "full2", "full100", "full0", "full1"};
  for (std::size_t k = 0; k < 5; ++k) {
    Scan scan = scans[k];
    scan.pose_cm = Pose::Identity();
    io::write_pcd(dir / (std::string(names[k]) + ".pcd"), scan, io::PcdEncoding::kBinary);
  }
  const io::Survey survey = io::read_survey(dir.path());
  std::vector<std::string> order;
  for (const Scan& scan : survey.scans) order.push_back(scan.name);
  EXPECT_EQ(order, (std::vector<std::string>{"full0", "full1", "full2", "full10", "full100"}));
  // KITTI numbers of different widths too.
  TempDir kitti;
  io::write_kitti_bin(kitti / "9.bin", scans[0]);
  io::write_kitti_bin(kitti / "10.bin", scans[1]);
  const io::Survey numbered = io::read_survey(kitti.path());
  ASSERT_EQ(numbered.scans.size(), 2u);
  EXPECT_EQ(numbered.scans[0].name, "9");
}

TEST(Survey, PoseFilesMayUseCommasAndReferencePosesWorkForAnySurvey) {
  TempDir dir;
  const auto scans = sample_scans(2);
  for (std::size_t k = 0; k < 2; ++k) {
    Scan scan = scans[k];
    scan.pose_cm = Pose::Identity();
    io::write_pcd(dir / ("s" + std::to_string(k) + ".pcd"), scan, io::PcdEncoding::kBinary);
  }
  // Two 4x4 matrices as CSV (4 lines each, comma and space separated), in metres.
  std::string csv;
  for (const Scan& scan : scans) {
    for (int row = 0; row < 4; ++row) {
      for (int col = 0; col < 4; ++col) {
        const double value = col == 3 && row < 3 ? scan.pose_cm(row, col) / 100.0 : scan.pose_cm(row, col);
        char text[40];
        std::snprintf(text, sizeof text, "%.17g%s", value, col < 3 ? ", " : "\n");
        csv += text;
      }
    }
  }
  TempDir poses;
  write_text(poses / "poses.csv", csv);
  io::SurveyReadSettings settings;
  settings.initial_poses = poses / "poses.csv";
  settings.reference_poses = poses / "poses.csv";
  const io::Survey survey = io::read_survey(dir.path(), settings);
  ASSERT_TRUE(survey.truth_cm.has_value());
  for (std::size_t k = 0; k < 2; ++k) {
    EXPECT_LT((survey.scans[k].pose_cm - scans[k].pose_cm).cwiseAbs().maxCoeff(), 1e-6);
    EXPECT_LT(((*survey.truth_cm)[k] - scans[k].pose_cm).cwiseAbs().maxCoeff(), 1e-6);
  }
  std::size_t fourth_line_end = 0;
  for (int line = 0; line < 4; ++line) fourth_line_end = csv.find('\n', fourth_line_end) + 1;
  // One matrix for two scans: a pair's relative transform (the second scan in the first's frame),
  // as fast_gicp's relative.txt, so the reference poses are {identity, that matrix}.
  write_text(poses / "short.csv", csv.substr(0, fourth_line_end));
  settings.reference_poses = poses / "short.csv";
  const io::Survey pair = io::read_survey(dir.path(), settings);
  ASSERT_TRUE(pair.truth_cm.has_value());
  EXPECT_EQ((*pair.truth_cm)[0], Pose::Identity());
  EXPECT_LT(((*pair.truth_cm)[1] - scans[0].pose_cm).cwiseAbs().maxCoeff(), 1e-6);
  // One pose of a trajectory (a TUM line) is not a relative transform: still the count's error.
  write_text(poses / "short.tum", "0 1 2 3 0 0 0 1\n");
  settings.reference_poses = poses / "short.tum";
  expect_input_error([&] { io::read_survey(dir.path(), settings); }, {"short.tum", "has 1 poses, the survey has 2 scans"});
}

TEST(Survey, AThreeFloatBinUnderKittisNameIsRefusedForWhatItIs) {
  TempDir not_sixteen;  // 301 points x 12 bytes = 3612 bytes: divides by 12, not by 16
  io::write_kitti_bin(not_sixteen / "000000.bin", test::random_scan(301, -2000.0f, 2000.0f, 5), 3);
  expect_input_error([&] { io::read_survey(not_sixteen.path()); },
                     {"000000.bin", "multiple of 12 bytes, not of 16", "3 float32 per point"});
  TempDir sixteen;  // 400 points x 12 bytes = 4800 bytes: divides by 16 too; a "reflectance" is negative
  Scan four_hundred = test::random_scan(400, -2000.0f, 2000.0f, 7);
  io::write_kitti_bin(sixteen / "000000.bin", four_hundred, 3);
  expect_input_error([&] { io::read_survey(sixteen.path()); }, {"000000.bin", "is no reflectance", "3 float32 per point"});
  TempDir kitti;  // KITTI's own 4 floats, reflectance 0: read
  io::write_kitti_bin(kitti / "000000.bin", four_hundred, 4);
  EXPECT_EQ(io::read_survey(kitti.path()).scans[0].size(), 400u);
}

TEST(Survey, WriterRefusesFoldersWithLeftoverScans) {
  TempDir dir;
  io::write_uos_survey(dir.path(), sample_scans(3));
  EXPECT_THROW(io::write_uos_survey(dir.path(), sample_scans(2)), OutputError);
  EXPECT_NO_THROW(io::write_uos_survey(dir.path(), sample_scans(3)));  // overwriting the same scans is fine
  EXPECT_THROW(io::write_uos_survey(dir.path(), sample_scans(3), std::vector<Pose>(2)), std::invalid_argument);
  // A stale truth/ would be read back as the new survey's truth.
  EXPECT_NO_THROW(io::write_uos_survey(dir.path(), sample_scans(3), std::vector<Pose>(3, Pose::Identity())));
  EXPECT_THROW(io::write_uos_survey(dir.path(), sample_scans(3)), OutputError);
}

}  // namespace
}  // namespace minemap
