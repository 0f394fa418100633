// ASCII xyz (io/xyz.cpp): CloudCompare's and PDAL's text exports read with their columns, bad lines
// named at their line, and a folder of them mapped as a survey (the same poses as its PLY twin).
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "io_test_helpers.hpp"
#include "minemap/core/error.hpp"
#include "minemap/io/formats.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

namespace fs = std::filesystem;
using test::TempDir;
using test::write_text;

std::string error_of(const fs::path& path) {
  try {
    io::read_xyz(path);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(IoXyz, ColumnsByCountMetresAndAttributes) {
  TempDir dir;
  write_text(dir / "a.xyz", "1 2 3\n4.5,5,6\n");
  const Scan three = io::read_xyz(dir / "a.xyz");
  ASSERT_EQ(three.size(), 2u);
  EXPECT_NEAR(three.file_point(1).x(), 450.0, 1e-4);  // metres to cm, the file's frame kept
  EXPECT_TRUE(three.attributes.intensity.empty());
  write_text(dir / "b.xyz", "1 2 3 0.25\n4 5 6 0.75\n");
  EXPECT_EQ(io::read_xyz(dir / "b.xyz").attributes.intensity, (std::vector<float>{0.25f, 0.75f}));
  write_text(dir / "c.txt", "1;2;3;255;0;16\n4;5;6;1;2;3\n");
  const Scan colour = io::read_xyz(dir / "c.txt");
  ASSERT_EQ(colour.attributes.rgb.size(), 2u);
  EXPECT_EQ(colour.attributes.rgb[0], 0xFF0010u);
  // Six values that are not colours (normals): x y z kept, the rest skipped.
  write_text(dir / "d.xyz", "1 2 3 0.1 0.2 0.97\n4 5 6 0 0 1\n");
  const Scan normals = io::read_xyz(dir / "d.xyz");
  EXPECT_TRUE(normals.attributes.rgb.empty());
  EXPECT_EQ(normals.size(), 2u);
  // Seven: x y z, colour, intensity (CloudCompare's order).
  write_text(dir / "e.xyz", "1 2 3 10 20 30 0.5\n");
  const Scan seven = io::read_xyz(dir / "e.xyz");
  EXPECT_EQ(seven.attributes.rgb, (std::vector<std::uint32_t>{0x0A141Eu}));
  EXPECT_EQ(seven.attributes.intensity, (std::vector<float>{0.5f}));
}

TEST(IoXyz, AHeaderOfNamesPicksTheColumns) {
  TempDir dir;
  write_text(dir / "cc.txt", "//X,Y,Z,Nx,Ny,Nz,R,G,B,scalar_Intensity\n1,2,3,0,0,1,7,8,9,42\n");
  const Scan scan = io::read_xyz(dir / "cc.txt");
  ASSERT_EQ(scan.size(), 1u);
  EXPECT_EQ(scan.attributes.rgb, (std::vector<std::uint32_t>{0x070809u}));
  EXPECT_EQ(scan.attributes.intensity, (std::vector<float>{42.0f}));
  write_text(dir / "pdal.txt", "Intensity,X,Y,Z\n5,1,2,3\n");
  const Scan pdal = io::read_xyz(dir / "pdal.txt");
  EXPECT_NEAR(pdal.file_point(0).x(), 100.0, 1e-4);
  EXPECT_EQ(pdal.attributes.intensity, (std::vector<float>{5.0f}));
}

TEST(IoXyz, BadLinesAreNamedAtTheirLine) {
  TempDir dir;
  write_text(dir / "a.xyz", "1 2 3\n4 5 6\n7 8\n");
  EXPECT_NE(error_of(dir / "a.xyz").find("a.xyz:3: expected at least 3 values"), std::string::npos)
      << error_of(dir / "a.xyz");
  write_text(dir / "b.xyz", "1 2 3\n4 5 6 7\n");
  EXPECT_NE(error_of(dir / "b.xyz").find("b.xyz:2: expected 3 values as on line 1, found 4"), std::string::npos)
      << error_of(dir / "b.xyz");
  write_text(dir / "c.xyz", "1 2 3\n4 inf 6\n");
  EXPECT_NE(error_of(dir / "c.xyz").find("c.xyz:2:"), std::string::npos) << error_of(dir / "c.xyz");
  write_text(dir / "d.xyz", "1 2 3\n4 x 6\n");
  EXPECT_NE(error_of(dir / "d.xyz").find("'x' is not a number"), std::string::npos) << error_of(dir / "d.xyz");
  write_text(dir / "e.xyz", "");
  EXPECT_NE(error_of(dir / "e.xyz").find("no points (empty file)"), std::string::npos);
  write_text(dir / "f.xyz", "nan 1 2\n");
  EXPECT_NE(error_of(dir / "f.xyz").find("all 1 are NaN"), std::string::npos) << error_of(dir / "f.xyz");
}

/// The sim's scans as both a PLY survey of floats and an xyz one (each float written with 17 digits,
/// so both files hold the same numbers): mapped, the same poses bit for bit.
TEST(IoXyz, AFolderOfXyzFilesMapsAsItsPlyTwin) {
  TempDir dir;
  const fs::path sim = dir / "sim";
  ASSERT_EQ(test::run_cli("simulate --out " + sim.string() + " --scans 3"), 0);
  fs::create_directories(dir / "ply");
  fs::create_directories(dir / "xyz");
  for (const char* name : {"scan000", "scan001", "scan002"}) {
    Scan scan = io::read_uos_points(sim / (std::string(name) + ".3d"));
    const Pose pose = euler_to_pose(io::read_uos_pose(sim / (std::string(name) + ".pose")));
    std::vector<Eigen::Vector3d> points;
    std::string text = "// a CloudCompare-like export\n";
    char line[128];
    for (std::size_t i = 0; i < scan.size(); ++i) {
      // World frame (the truth-free initial pose), right-handed z up, metres, as float.
      const Eigen::Vector3d world = pose.block<3, 3>(0, 0) * scan.file_point(i) + pose.block<3, 1>(0, 3);
      const Eigen::Vector3f m = threedtk_to_right_handed(world, 0.01).cast<float>();
      points.push_back(m.cast<double>());
      std::snprintf(line, sizeof line, "%.17g %.17g %.17g\n", double(m.x()), double(m.y()), double(m.z()));
      text += line;
    }
    io::PlyStreamWriter ply(dir / "ply" / (std::string(name) + ".ply"), {});
    ply.write(points, {});
    ply.finish();
    write_text(dir / "xyz" / (std::string(name) + ".txt"), text);
  }
  write_text(dir / "xyz" / "README.txt", "Scans of the simulated drive, exported as text.\n");
  std::string output;
  for (const char* kind : {"ply", "xyz"}) {
    ASSERT_EQ(test::run_cli(std::string("map ") + (dir / kind).string() + " --out " + (dir / kind).string() +
                                "-out --backend cpu --quiet --accept-doubtful",
                            &output),
              0)
        << output;
  }
  const auto report = [&](const char* kind) {
    std::ifstream in(dir / (std::string(kind) + "-out") / "report.json");
    return nlohmann::json::parse(in);
  };
  const nlohmann::json a = report("ply"), b = report("xyz");
  EXPECT_EQ(b["format"], "xyz");
  ASSERT_EQ(b["scans"].size(), 3u) << "README.txt is not a scan";
  for (std::size_t s = 0; s < 3; ++s) EXPECT_EQ(a["scans"][s]["pose"], b["scans"][s]["pose"]) << s;
}

TEST(IoXyz, ASingleFileIsRefusedWithWhatToDo) {
  TempDir dir;
  write_text(dir / "one.xyz", "1 2 3\n4 5 6\n7 8 9\n");
  std::string output;
  EXPECT_EQ(test::run_cli("map " + (dir / "one.xyz").string() + " --out " + (dir / "out").string(), &output), 3);
  EXPECT_NE(output.find("is a file, not a folder"), std::string::npos) << output;
  EXPECT_NE(output.find("put it in a folder of its own"), std::string::npos) << output;
}

}  // namespace
}  // namespace minemap
