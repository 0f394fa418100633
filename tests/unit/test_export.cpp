// The map a surveyor takes away: readers keep the attributes their files carry; a survey in world
// coordinates is mapped near zero and exported in its own coordinates; `minemap export` writes every
// point of every scan with its attributes and scan index, in metres, right-handed, z up, streamed,
// whole or not at all; map.ply and the other person-facing outputs are in metres, z up.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <tuple>
#include <nlohmann/json.hpp>

#include "io_test_helpers.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/report/survey_export.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

using test::run_cli;
using test::TempDir;

/// A PLY file's header and its vertex records (binary little-endian), split.
struct PlyFile {
  std::string header;
  std::string data;
  std::uint64_t vertices = 0;
};

PlyFile read_ply_file(const std::filesystem::path& path) {
  PlyFile ply;
  const std::string bytes = test::read_text(path);
  const std::size_t end = bytes.find("end_header\n");
  EXPECT_NE(end, std::string::npos);
  ply.header = bytes.substr(0, end);
  ply.data = bytes.substr(end + 11);
  const std::size_t at = ply.header.find("element vertex ");
  ply.vertices = std::stoull(ply.header.substr(at + 15));
  return ply;
}

Scan scan_with_attributes(std::size_t n) {
  Scan scan = test::random_scan(n, -500, 500, 7, "attributes");
  for (std::size_t i = 0; i < n; ++i) {
    PointValues v;
    v.intensity = 0.25f * static_cast<float>(i);
    v.rgb = static_cast<std::uint32_t>(0x10203 * i) & 0xFFFFFF;
    v.time_s = 1000.0 + 0.001 * static_cast<double>(i);
    v.ring = static_cast<std::uint16_t>(i % 64);
    scan.attributes.push_back(v, kIntensity | kColour | kTime | kRing);
  }
  return scan;
}

TEST(Attributes, PcdKeepsIntensityColourTimeAndRingInEveryEncoding) {
  TempDir dir;
  const Scan scan = scan_with_attributes(500);
  for (const io::PcdEncoding encoding : {io::PcdEncoding::kAscii, io::PcdEncoding::kBinary, io::PcdEncoding::kBinaryCompressed}) {
    const auto path = dir / "a.pcd";
    io::write_pcd(path, scan, encoding);
    const Scan read = io::read_pcd(path);
    ASSERT_EQ(read.size(), scan.size());
    EXPECT_EQ(read.attributes.intensity, scan.attributes.intensity);
    EXPECT_EQ(read.attributes.rgb, scan.attributes.rgb);
    EXPECT_EQ(read.attributes.time_s, scan.attributes.time_s);
    EXPECT_EQ(read.attributes.ring, scan.attributes.ring);
    // Asked for the intensity alone (as mapping reads), the rest costs nothing.
    io::ReadSettings intensity_only;
    intensity_only.attributes = kIntensity;
    const Scan slim = io::read_pcd(path, intensity_only);
    EXPECT_EQ(slim.attributes.columns(), kIntensity);
    EXPECT_TRUE(slim.attributes.rgb.empty() && slim.attributes.time_s.empty() && slim.attributes.ring.empty());
  }
}

TEST(Attributes, ADroppedNanPointDropsItsAttributes) {
  TempDir dir;
  const auto path = dir / "nan.pcd";
  test::write_text(path,
                   "VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 4\nHEIGHT 1\n"
                   "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n1 2 3 10\nnan nan nan 20\n4 5 6 30\n7 8 9 40\n");
  const Scan scan = io::read_pcd(path);
  ASSERT_EQ(scan.size(), 3u);
  EXPECT_EQ(scan.attributes.intensity, (std::vector<float>{10, 30, 40}));
}

TEST(Attributes, PlyKittiAndUosKeepTheirs) {
  TempDir dir;
  const auto ply = dir / "a.ply";
  test::write_text(ply, "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                        "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float scalar_intensity\n"
                        "end_header\n1 2 3 255 128 0 0.5\n4 5 6 1 2 3 7\n");
  const Scan from_ply = io::read_ply(ply);
  EXPECT_EQ(from_ply.attributes.rgb, (std::vector<std::uint32_t>{0xFF8000, 0x010203}));
  EXPECT_EQ(from_ply.attributes.intensity, (std::vector<float>{0.5f, 7.0f}));
  Scan kitti = test::random_scan(10, -100, 100, 3);
  for (int i = 0; i < 10; ++i) kitti.attributes.intensity.push_back(0.1f * static_cast<float>(i));
  io::write_kitti_bin(dir / "000000.bin", kitti);
  EXPECT_EQ(io::read_kitti_bin(dir / "000000.bin").attributes.intensity, kitti.attributes.intensity);
  test::write_text(dir / "scan000.3d", "1 2 3 17\n4 5 6 18\n7 8 9 19\n");
  EXPECT_EQ(io::read_uos_points(dir / "scan000.3d").attributes.intensity, (std::vector<float>{17, 18, 19}));
}

TEST(Attributes, TheStreamedPlyWriterWritesEveryColumnAndAppearsOnlyWhenFinished) {
  TempDir dir;
  const auto path = dir / "cloud.ply";
  const Scan scan = scan_with_attributes(100);
  std::vector<Eigen::Vector3d> points;
  for (std::size_t i = 0; i < scan.size(); ++i) points.push_back(scan.file_point(i) / 100.0);
  {
    io::PlyStreamWriter writer(path, {.double_coordinates = true, .attributes = kIntensity | kColour | kTime | kRing,
                                      .scan_index = true, .comments = {"a test"}});
    writer.write(points, scan.attributes, 7);
    EXPECT_FALSE(std::filesystem::exists(path));  // not before it is finished
  }
  EXPECT_FALSE(std::filesystem::exists(path));  // destroyed unfinished: nothing, no temp file
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
  io::PlyStreamWriter writer(path, {.double_coordinates = true, .attributes = kIntensity | kColour | kTime | kRing,
                                    .scan_index = true, .comments = {"a test"}});
  writer.write(points, scan.attributes, 7);
  writer.write(points, scan.attributes, 8);
  writer.finish();
  const Scan back = io::read_ply(path);  // minemap's own reader: coordinates and attributes
  ASSERT_EQ(back.size(), 200u);
  for (std::size_t i = 0; i < 100; ++i) EXPECT_LT((back.file_point(i) - scan.file_point(i)).norm(), 1e-3) << i;
  EXPECT_EQ(std::vector<float>(back.attributes.intensity.begin(), back.attributes.intensity.begin() + 100),
            scan.attributes.intensity);
  EXPECT_EQ(std::vector<std::uint32_t>(back.attributes.rgb.begin(), back.attributes.rgb.begin() + 100),
            scan.attributes.rgb);
  EXPECT_EQ(std::vector<std::uint16_t>(back.attributes.ring.begin() + 100, back.attributes.ring.end()),
            scan.attributes.ring);
  const PlyFile file = read_ply_file(path);
  EXPECT_NE(file.header.find("comment a test"), std::string::npos);
  EXPECT_NE(file.header.find("property uint scan"), std::string::npos);
}

/// The simulated drive mapped into `out`.
void map_simulated(const TempDir& dir, int scans, const std::string& out, const std::string& extra = "") {
  std::string output;
  ASSERT_EQ(run_cli("simulate --out " + (dir / "survey").string() + " --scans " + std::to_string(scans), &output), 0)
      << output;
  ASSERT_EQ(run_cli("map " + (dir / "survey").string() + " --out " + out + " --backend cpu --quiet" + extra, &output), 0)
      << output;
}

nlohmann::json report_of(const std::filesystem::path& out) {
  return nlohmann::json::parse(test::read_text(out / "report.json"));
}

TEST(Export, EveryPointOfEveryScanInMetresZUpWithItsScan) {
  TempDir dir;
  const std::string out = (dir / "out").string();
  map_simulated(dir, 4, out);
  std::string output;
  ASSERT_EQ(run_cli("export " + out + " --to " + (dir / "all.ply").string(), &output), 0) << output;
  const nlohmann::json report = report_of(out);
  std::uint64_t points_in = 0;
  for (const auto& scan : report["scans"]) points_in += scan["points_in"].get<std::uint64_t>();
  const PlyFile ply = read_ply_file(dir / "all.ply");
  EXPECT_EQ(ply.vertices, points_in);  // every input point
  EXPECT_NE(ply.header.find("metres, right-handed, z up"), std::string::npos) << ply.header;
  // Scan 1's points as the export placed them: its file's points, moved by its registered pose
  // (report.json, 3DTK frame, cm), then turned to right-handed z up, in metres.
  const Scan raw = io::read_uos_points(dir / "survey" / "scan001.3d");
  Pose pose;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) pose(r, c) = report["scans"][1]["pose"][r][c].get<double>();
  }
  const std::size_t record = 3 * 4 + 4;  // float x y z, uint scan
  const std::size_t first = raw.size() == 0 ? 0 : report["scans"][0]["points_in"].get<std::size_t>();
  for (std::size_t i = 0; i < raw.size(); i += 997) {
    float xyz[3];
    std::uint32_t scan = 0;
    std::memcpy(xyz, ply.data.data() + (first + i) * record, 12);
    std::memcpy(&scan, ply.data.data() + (first + i) * record + 12, 4);
    const Eigen::Vector3d world_cm = pose.block<3, 3>(0, 0) * raw.file_point(i) + pose.block<3, 1>(0, 3);
    const Eigen::Vector3d expected = threedtk_to_right_handed(world_cm, 0.01);
    EXPECT_LT((Eigen::Vector3f(xyz[0], xyz[1], xyz[2]).cast<double>() - expected).norm(), 1e-5) << i;
    EXPECT_EQ(scan, 1u);
  }
  // --voxel-cm thins each scan; --scans picks; --frame survey keeps 3DTK's frame and cm.
  ASSERT_EQ(run_cli("export " + out + " --to " + (dir / "thin.ply").string() + " --voxel-cm 20 --scans scan000,scan002 " +
                        "--frame survey --quiet",
                    &output),
            0)
      << output;
  const PlyFile thin = read_ply_file(dir / "thin.ply");
  EXPECT_GT(thin.vertices, 1000u);
  EXPECT_LT(thin.vertices, (report["scans"][0]["points_in"].get<std::uint64_t>() +
                            report["scans"][2]["points_in"].get<std::uint64_t>()) / 4);
  EXPECT_NE(thin.header.find("3DTK frame"), std::string::npos) << thin.header;
}

TEST(Export, APcdSurveyKeepsItsIntensitiesExactly) {
  TempDir dir;
  const auto data = test::shared_data_dir() / "mine_jinchuan_pcr";
  std::string output;
  ASSERT_EQ(run_cli("map " + data.string() + " --out " + (dir / "out").string() + " --quiet", &output), 0) << output;
  ASSERT_EQ(run_cli("export " + (dir / "out").string() + " --to " + (dir / "mine.ply").string() + " --quiet", &output), 0)
      << output;
  std::vector<float> expected;
  for (const char* file : {"2025-04-21-11-04-46.pcd", "2025-05-13-10-25-38.pcd"}) {
    const Scan scan = io::read_pcd(data / file);
    expected.insert(expected.end(), scan.attributes.intensity.begin(), scan.attributes.intensity.end());
  }
  const Scan exported = io::read_ply(dir / "mine.ply");
  std::vector<float> got = exported.attributes.intensity;
  ASSERT_EQ(got.size(), expected.size());
  std::sort(got.begin(), got.end());
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(got, expected);  // the same multiset
  const PlyFile ply = read_ply_file(dir / "mine.ply");
  EXPECT_NE(ply.header.find("property float intensity"), std::string::npos);
  // map.ply: the matching's points with their (voxel mean) intensities and scans, z up, metres.
  const PlyFile map = read_ply_file(dir / "out" / "map.ply");
  EXPECT_NE(map.header.find("property float intensity"), std::string::npos) << map.header;
  EXPECT_NE(map.header.find("property uint scan"), std::string::npos) << map.header;
}

Pose pose_of(const nlohmann::json& rows) {
  Pose pose;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) pose(r, c) = rows[r][c].get<double>();
  }
  return pose;
}

TEST(Export, ASurveyInWorldCoordinatesMapsNearZeroAndExportsInItsOwnCoordinates) {
  TempDir dir;
  const auto data = test::shared_data_dir() / "fast_gicp_pair";
  const Eigen::Vector3d offset_m(500000.0, 6000000.0, 100.0);  // UTM-size
  std::filesystem::create_directories(dir / "local");
  std::filesystem::create_directories(dir / "world");
  std::vector<std::vector<Eigen::Vector3d>> world_points;
  for (const char* file : {"251370668.pcd", "251371071.pcd"}) {
    const Scan scan = io::read_pcd(data / file);
    std::vector<Eigen::Vector3d> local, world;
    for (std::size_t i = 0; i < scan.size(); ++i) {
      // The local file stores float metres; its world copy holds each stored value plus the
      // offset, in double, as a surveyor's file holds it.
      local.push_back((scan.file_point(i) / 100.0).cast<float>().cast<double>());
      world.push_back(local.back() + offset_m);
    }
    for (const auto& [folder, points, wide] : {std::tuple{"local", &local, false}, std::tuple{"world", &world, true}}) {
      io::PlyStreamWriter::Layout layout;  // not designated: GCC 12 warns of the unnamed members
      layout.double_coordinates = wide;
      io::PlyStreamWriter ply(dir / folder / (scan.name + ".ply"), layout);
      ply.write(*points, {});
      ply.finish();
    }
    world_points.push_back(std::move(world));
  }
  std::string output;
  for (const char* name : {"local", "world"}) {
    ASSERT_EQ(run_cli(std::string("map ") + (dir / name).string() + " --out " +
                          (dir / (std::string(name) + "-out")).string() + " --backend cpu --quiet --accept-doubtful",
                      &output),
              0)
        << output;
  }
  const nlohmann::json local = report_of(dir / "local-out"), world = report_of(dir / "world-out");
  EXPECT_FALSE(local.contains("origin"));
  ASSERT_TRUE(world.contains("origin"));
  Eigen::Vector3d origin_m, d;
  for (int k = 0; k < 3; ++k) {
    origin_m[k] = world["origin"][k].get<double>();
    EXPECT_EQ(origin_m[k], 100.0 * std::round(origin_m[k] / 100.0)) << "a multiple of 100 m";
    d[k] = offset_m[k] - origin_m[k];
  }
  // The offset is whole hundreds of metres, so the local origin takes it all (io::kLocalOriginGrid_cm):
  // the copy reads to the original's floats in the original's frame (but where a coordinate near
  // zero lost its last bits to the offset in the world file's double) and maps to the original's
  // poses within a micrometre, not merely as near as the voxel grid's phase would let two
  // differently placed copies agree (centimetres).
  EXPECT_EQ(d, Eigen::Vector3d::Zero()) << "origin " << origin_m.transpose();
  for (std::size_t s = 0; s < 2; ++s) {
    const Pose a = pose_of(local["scans"][s]["pose"]), b = pose_of(world["scans"][s]["pose"]);
    EXPECT_LT((b.block<3, 1>(0, 3) - a.block<3, 1>(0, 3)).norm(), 1e-4) << "scan " << s << " (cm)";
    EXPECT_LT(rotation_angle_deg(rigid_inverse(a) * b), 1e-4) << "scan " << s;
  }
  // Its map lies near zero, where the original's does moved by d (its views draw the same map,
  // not a dot under a 100 km scale bar).
  const Scan map_local = io::read_ply(dir / "local-out" / "map.ply");
  const Scan map_world = io::read_ply(dir / "world-out" / "map.ply");
  ASSERT_GT(map_world.size(), 1000u);
  Eigen::Vector3d mean_local = Eigen::Vector3d::Zero(), mean_world = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < map_local.size(); ++i) mean_local += map_local.file_point(i) / 100.0;
  for (std::size_t i = 0; i < map_world.size(); ++i) mean_world += map_world.file_point(i) / 100.0;
  mean_local /= double(map_local.size());
  mean_world /= double(map_world.size());
  EXPECT_LT((mean_world - mean_local - d).norm(), 0.05) << "map.ply: the same map, moved by d";
  EXPECT_LT(mean_world.norm(), 1000.0);
  // Exported: back in world coordinates, double, each point where the world run's pose puts its
  // file point, to the millimetre: pose applied to (file point - origin), plus the origin.
  ASSERT_EQ(run_cli("export " + (dir / "world-out").string() + " --to " + (dir / "world.ply").string() + " --quiet",
                    &output),
            0)
      << output;
  const PlyFile w = read_ply_file(dir / "world.ply");
  EXPECT_NE(w.header.find("property double x"), std::string::npos);
  ASSERT_EQ(w.vertices, world_points[0].size() + world_points[1].size());
  std::size_t checked = 0;
  for (std::size_t s = 0, first = 0; s < 2; first += world_points[s].size(), ++s) {
    const Pose pose = pose_of(world["scans"][s]["pose"]);
    for (std::size_t i = 0; i < world_points[s].size(); i += 997, ++checked) {
      double xyz[3];
      std::memcpy(xyz, w.data.data() + (first + i) * (24 + 4), 24);
      const Eigen::Vector3d want =
          pose.block<3, 3>(0, 0) * (world_points[s][i] - origin_m) + pose.block<3, 1>(0, 3) + origin_m;
      EXPECT_LT((Eigen::Vector3d(xyz[0], xyz[1], xyz[2]) - want).norm(), 1e-3) << "scan " << s << " point " << i;
    }
  }
  EXPECT_GT(checked, 100u);
}

TEST(Export, AStopLeavesNothingAndAnExistingFileAsItWas) {
  TempDir dir;
  const std::string out = (dir / "out").string();
  map_simulated(dir, 3, out);
  const auto path = dir / "keep.ply";
  test::write_text(path, "the old file");
  SurveyExport scans(out, {});
  int asked = 0;
  const ExportSummary summary = write_export_ply(scans, path, [&] { return ++asked > 1; });
  EXPECT_FALSE(summary.completed);
  EXPECT_EQ(test::read_text(path), "the old file");
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().filename().string().find(".minemap-tmp-"), std::string::npos) << entry.path();
  }
}

TEST(Export, AReportThatIsNotAMapsOrAChangedSurveyIsAnErrorNamingTheFile) {
  TempDir dir;
  test::expect_input_error([&] { SurveyExport(dir.path(), {}); }, {(dir / "report.json").string()});
  test::write_text(dir / "report.json", "{\"unit\": \"cm\"}");
  test::expect_input_error([&] { SurveyExport(dir.path(), {}); }, {"report.json", "\"survey\""});
  const std::string out = (dir / "out").string();
  map_simulated(dir, 3, out);
  test::expect_input_error([&] { SurveyExport(out, {.scans = {"scan009"}}); }, {"report.json", "scan009"});
  // A scan file that changed since the map: refused, naming it.
  test::write_text(dir / "survey" / "scan001.3d", "1 2 3\n4 5 6\n7 8 9\n");
  SurveyExport scans(out, {});
  scans.next();
  test::expect_input_error([&] { scans.next(); }, {"scan001.3d", "changed since it was mapped"});
  std::string output;
  EXPECT_EQ(run_cli("export " + out + " --to " + (dir / "x.ply").string(), &output), 10) << output;
  EXPECT_EQ(run_cli("export " + out + " --to " + (dir / "x.xyz").string(), &output), 2) << output;
  EXPECT_NE(output.find("unknown export format"), std::string::npos) << output;
  EXPECT_EQ(run_cli("export " + out + " --to " + (dir / "x.laz").string(), &output), 2) << output;
  EXPECT_NE(output.find("Python package"), std::string::npos) << output;
}

}  // namespace
}  // namespace minemap
