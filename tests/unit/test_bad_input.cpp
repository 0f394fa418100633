// The bad-input table (docs/bad-input.md) as tests: one row per reader and case, checking the kind
// of InputError (and so the exit code), that the message names the file and the line (text) or byte
// (binary); then the `minemap map` rows end to end: exit code, message, and an output folder left as
// it was. Every input is fixed content (the simulated survey is seeded), so a failure replays.
#include <gtest/gtest.h>

#include <array>
#include <cstring>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <fstream>
#include <vector>

#include "io_test_helpers.hpp"
#include "minemap/cli/exit_codes.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace minemap {
namespace {

namespace fs = std::filesystem;
using test::at_byte;
using test::at_line;
using test::TempDir;
using test::write_text;

using Xyz = std::array<double, 3>;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

/// Four plain points, in the file's unit.
const std::vector<Xyz> kGood{{1, 2, 3}, {4, 5, 6}, {7, 8, 9}, {0.5, 0.25, 0}};

/// 4 KiB of fixed bytes that are no format at all (a multiplicative hash of the index).
std::string garbage() {
  std::string bytes(4096, '\0');
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    bytes[i] = static_cast<char>(((static_cast<std::uint64_t>(i) * 2654435761u) >> 13) & 0xff);
  }
  return bytes;
}

template <class T>
void put(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

std::string number(double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.9g", v);  // "nan", "inf" as C prints them
  return buffer;
}

std::string text_points(const std::vector<Xyz>& points) {
  std::string out;
  for (const Xyz& p : points) out += number(p[0]) + " " + number(p[1]) + " " + number(p[2]) + "\n";
  return out;
}

std::string pcd_header(std::uint64_t count, const std::string& data) {
  const std::string n = std::to_string(count);
  return "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " + n + "\nHEIGHT 1\n"
         "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS " + n + "\nDATA " + data + "\n";
}

/// PCD with `points`; the header claims `count` points (default: as many as there are).
std::string pcd(const std::vector<Xyz>& points, const std::string& data, std::uint64_t count = 0) {
  std::string out = pcd_header(count ? count : points.size(), data);
  if (data == "ascii") return out + text_points(points);
  if (data == "binary") {
    for (const Xyz& p : points) {
      for (double v : p) put(out, static_cast<float>(v));
    }
    return out;
  }
  std::string soa;  // binary_compressed: x of all points, then y, then z; LZF literal runs of 32
  for (int axis = 0; axis < 3; ++axis) {
    for (const Xyz& p : points) put(soa, static_cast<float>(p[static_cast<std::size_t>(axis)]));
  }
  std::string lzf;
  for (std::size_t i = 0; i < soa.size(); i += 32) {
    const std::size_t run = std::min<std::size_t>(32, soa.size() - i);
    lzf += static_cast<char>(run - 1);
    lzf += soa.substr(i, run);
  }
  put(out, static_cast<std::uint32_t>(lzf.size()));
  put(out, static_cast<std::uint32_t>(soa.size()));
  return out + lzf;
}

std::string ply_header(std::uint64_t count, bool binary) {
  return std::string("ply\nformat ") + (binary ? "binary_little_endian" : "ascii") + " 1.0\nelement vertex " +
         std::to_string(count) + "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
}

std::string ply(const std::vector<Xyz>& points, bool binary, std::uint64_t count = 0) {
  std::string out = ply_header(count ? count : points.size(), binary);
  if (!binary) return out + text_points(points);
  for (const Xyz& p : points) {
    for (double v : p) put(out, static_cast<float>(v));
  }
  return out;
}

std::string kitti(const std::vector<Xyz>& points) {
  std::string out;
  for (const Xyz& p : points) {
    for (double v : p) put(out, static_cast<float>(v));
    put(out, 0.5f);  // intensity
  }
  return out;
}

// ---- the readers' table ------------------------------------------------------------------------

using ReadFn = std::function<void(const fs::path&, const io::ReadSettings&)>;

/// A point format: how to write points in it, how to read it, where its data starts.
struct PointFormat {
  std::string name;
  std::string file_name;
  std::function<std::string(const std::vector<Xyz>&)> encode;
  ReadFn read;
  bool text;
  std::size_t header_lines;  ///< text: lines before the first point
  std::size_t header_bytes;  ///< binary: bytes before the first point (for 4 points)
};

std::vector<PointFormat> point_formats() {
  const auto read_scan = [](auto reader) {
    return [reader](const fs::path& p, const io::ReadSettings& s) { (void)reader(p, s); };
  };
  return {
      {"uos", "scan001.3d", text_points, read_scan([](auto& p, auto& s) { return io::read_uos_points(p, s); }), true, 0, 0},
      {"pcd ascii", "a.pcd", [](auto& p) { return pcd(p, "ascii"); },
       read_scan([](auto& p, auto& s) { return io::read_pcd(p, s); }), true, 10, 0},
      {"pcd binary", "b.pcd", [](auto& p) { return pcd(p, "binary"); },
       read_scan([](auto& p, auto& s) { return io::read_pcd(p, s); }), false, 0, pcd_header(4, "binary").size()},
      {"pcd binary_compressed", "c.pcd", [](auto& p) { return pcd(p, "binary_compressed"); },
       read_scan([](auto& p, auto& s) { return io::read_pcd(p, s); }), false, 0,
       pcd_header(4, "binary_compressed").size()},
      {"ply ascii", "a.ply", [](auto& p) { return ply(p, false); },
       read_scan([](auto& p, auto& s) { return io::read_ply(p, s); }), true, 7, 0},
      {"ply binary", "b.ply", [](auto& p) { return ply(p, true); },
       read_scan([](auto& p, auto& s) { return io::read_ply(p, s); }), false, 0, ply_header(4, true).size()},
      {"kitti bin", "000001.bin", kitti, read_scan([](auto& p, auto& s) { return io::read_kitti_bin(p, s); }), false, 0, 0},
  };
}

/// One row of the table: a file's content, how to read it, and the error it must give.
struct Row {
  std::string reader;
  std::string problem_case;  ///< the table's case ("truncated", "binary garbage", ...)
  std::string file_name;
  std::string content;
  ReadFn read;
  InputProblem expected;
  std::string where;    ///< ":LINE:" or "@byte N:" after the path; empty: only the path
  std::string message;  ///< a part of the message
  io::ReadSettings settings = {};
};

std::vector<Row> reader_rows() {
  std::vector<Row> rows;
  // Appended, not ":" + to_string(n): GCC 12 warns (-Wrestrict) about that temporary's insert.
  const auto line = [](std::size_t n) { return std::string(":").append(std::to_string(n)).append(":"); };
  const auto byte = [](std::size_t n) { return "@byte " + std::to_string(n) + ":"; };
  io::ReadSettings two_points;
  two_points.max_points = 2;
  io::ReadSettings unlimited;
  unlimited.max_points = std::numeric_limits<std::uint64_t>::max();

  for (const PointFormat& f : point_formats()) {
    const auto add = [&](std::string problem_case, std::string content, InputProblem expected, std::string where,
                         std::string message, io::ReadSettings settings = {}) {
      rows.push_back({f.name, std::move(problem_case), f.file_name, std::move(content), f.read, expected, std::move(where),
                      std::move(message), settings});
    };
    std::vector<Xyz> with_inf = kGood;
    with_inf[1][1] = kInf;
    // inf at point 1, y: its line, or its byte (compressed data: the block's first byte).
    std::string inf_where = f.text ? line(f.header_lines + 2) : byte(f.header_bytes + 12 + 4);
    if (f.name == "pcd binary_compressed") inf_where = byte(f.header_bytes + 8);
    if (f.name == "kitti bin") inf_where = byte(16 + 4);
    add("inf coordinate", f.encode(with_inf), InputProblem::kNonFinite, inf_where, "finite");
    add("all points NaN", f.encode(std::vector<Xyz>(4, Xyz{kNaN, kNaN, kNaN})), InputProblem::kNonFinite, "",
        "all 4 are NaN");
    add("empty file", "", InputProblem::kEmpty, "", "empty");
    add("binary garbage", garbage(), InputProblem::kMalformed, "", "");
  }
  const std::string good_uos = text_points(kGood);
  const auto uos_read = point_formats()[0].read;
  const auto pcd_read = point_formats()[1].read;
  const auto ply_read = point_formats()[4].read;
  const auto kitti_read = point_formats()[6].read;
  // Truncated: each format's own way of ending early.
  rows.push_back({"uos", "truncated", "scan001.3d", "1 2 3\n4 5 6\n7 8", uos_read, InputProblem::kTruncated, line(3),
                  "file ends inside this line"});
  rows.push_back({"pcd ascii", "truncated", "a.pcd", pcd_header(4, "ascii") + "1.5 2.5 3.5\n4.5 5.5 6.5\n7.5 8.",
                  pcd_read, InputProblem::kTruncated, line(13), "truncated"});
  rows.push_back({"pcd ascii", "truncated", "a.pcd", pcd_header(4, "ascii") + "1.5 2.5 3.5\n4.5 5.5 6.5\n7.5 8.5 9.5\n",
                  pcd_read, InputProblem::kTruncated, line(13), "only 3 of POINTS 4"});
  rows.push_back({"pcd binary", "truncated", "b.pcd", pcd(kGood, "binary").substr(0, pcd_header(4, "binary").size() + 30),
                  pcd_read, InputProblem::kTruncated, byte(pcd_header(4, "binary").size() + 30), "truncated"});
  const std::string compressed = pcd(kGood, "binary_compressed");
  rows.push_back({"pcd binary_compressed", "truncated", "c.pcd", compressed.substr(0, compressed.size() - 5), pcd_read,
                  InputProblem::kTruncated, byte(pcd_header(4, "binary_compressed").size()), "truncated"});
  rows.push_back({"pcd binary_compressed", "truncated", "c.pcd", pcd_header(4, "binary_compressed") + "abc", pcd_read,
                  InputProblem::kTruncated, byte(pcd_header(4, "binary_compressed").size()), "no block sizes"});
  rows.push_back({"ply ascii", "truncated", "a.ply", ply_header(4, false) + "1.5 2.5 3.5\n4.5 5.5 6.5\n7.5 8.5", ply_read,
                  InputProblem::kTruncated, line(10), "file ends inside this line"});
  rows.push_back({"ply ascii", "truncated", "a.ply", ply_header(2, false) + "1.5 2.5 3.5\n\n", ply_read,
                  InputProblem::kTruncated, line(9), "file ends after 1 of 2 vertex lines"});
  rows.push_back({"ply ascii", "truncated", "a.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n",
                  ply_read, InputProblem::kTruncated, line(4), "no end_header"});
  rows.push_back({"ply binary", "truncated", "b.ply", ply(kGood, true).substr(0, ply_header(4, true).size() + 30),
                  ply_read, InputProblem::kTruncated, byte(ply_header(4, true).size()), "file ends inside the vertices"});
  rows.push_back({"kitti bin", "truncated", "000001.bin", kitti(kGood).substr(0, 61), kitti_read,
                  InputProblem::kTruncated, byte(48), "truncated"});
  // A point's time that is not a number: its sweep could not be deskewed (the line of the point).
  rows.push_back({"pcd ascii", "NaN time", "t.pcd",
                  "VERSION 0.7\nFIELDS x y z time\nSIZE 4 4 4 8\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 3\nHEIGHT 1\n"
                  "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n1 2 3 0.0\n4 5 6 nan\n7 8 9 0.1\n",
                  pcd_read, InputProblem::kNonFinite, line(12), "time is not a finite number"});
  // Header counts beyond the limits: refused from the header, before anything is allocated.
  for (const char* data : {"ascii", "binary", "binary_compressed"}) {
    const std::string huge = pcd(kGood, data, 1'000'000'000'000);
    rows.push_back({std::string("pcd ") + data, "absurd header count", "h.pcd", huge, pcd_read,
                    InputProblem::kCountBeyondLimits, line(9), "claims 1000000000000 points, more than max_points"});
    // With no max_points limit the file size still refuses it (a 12 TB reserve would throw bad_alloc).
    rows.push_back({std::string("pcd ") + data, "absurd header count, no max_points", "h.pcd", huge, pcd_read,
                    std::string(data) == "binary_compressed" ? InputProblem::kMalformed : InputProblem::kTruncated, "",
                    "", unlimited});
  }
  for (const bool binary : {false, true}) {
    const std::string huge = ply(kGood, binary, 1'000'000'000'000);
    const std::string reader = binary ? "ply binary" : "ply ascii";
    rows.push_back({reader, "absurd header count", "h.ply", huge, ply_read, InputProblem::kCountBeyondLimits, line(3),
                    "claims 1000000000000 vertices, more than max_points"});
    rows.push_back({reader, "absurd header count, no max_points", "h.ply", huge, ply_read, InputProblem::kTruncated,
                    binary ? byte(ply_header(1'000'000'000'000, true).size()) : line(3), "", unlimited});
  }
  rows.push_back({"uos", "more points than max_points", "scan001.3d", good_uos, uos_read,
                  InputProblem::kCountBeyondLimits, line(3), "max_points", two_points});
  rows.push_back({"kitti bin", "more points than max_points", "000001.bin", kitti(kGood), kitti_read,
                  InputProblem::kCountBeyondLimits, "", "max_points", two_points});
  rows.push_back({"kitti bin", "binary garbage", "000001.bin", garbage(), kitti_read, InputProblem::kMalformed, byte(16),
                  "beyond 1e10 cm"});

  // Pose and trajectory files: no value can be dropped, so NaN is an error too.
  struct PoseFormat {
    std::string name, file_name, good, truncated;
    std::size_t truncated_line;
    std::string nan, infinite;  ///< one bad value, on line 1
    ReadFn read;
  };
  const auto read_poses = [](auto reader) {
    return [reader](const fs::path& p, const io::ReadSettings&) { (void)reader(p); };
  };
  const std::vector<PoseFormat> pose_formats{
      {"uos .pose", "scan001.pose", "1 2 3\n4 5 6\n", "1 2 3\n4 5", 2, "1 nan 3\n4 5 6\n", "1 inf 3\n4 5 6\n",
       read_poses([](auto& p) { return io::read_uos_pose(p); })},
      {"uos .frames", "scan001.frames", "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 1\n",
       "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1 1\n1 0 0 0 0 1", 2, "1 0 0 0 0 1 0 0 0 0 1 0 nan 0 0 1 1\n",
       "1 0 0 0 0 1 0 0 0 0 1 0 inf 0 0 1 1\n", read_poses([](auto& p) { return io::read_uos_frames(p); })},
      {"TUM", "poses.tum", "0 0 0 0 0 0 0 1\n", "0 0 0 0 0 0 0 1\n1 2 3 0 0", 2, "0 nan 0 0 0 0 0 1\n",
       "0 inf 0 0 0 0 0 1\n", read_poses([](auto& p) { return io::read_tum(p); })},
      {"KITTI poses", "poses.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n", "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0", 2,
       "1 0 0 nan 0 1 0 0 0 0 1 0\n", "1 0 0 inf 0 1 0 0 0 0 1 0\n",
       read_poses([](auto& p) { return io::read_kitti_poses(p); })},
      {"4x4 matrices", "poses.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "1 0 0 0\n0 1 0 0\n0 0 1 0\n", 3,
       "1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "1 0 0 inf\n0 1 0 0\n0 0 1 0\n0 0 0 1\n",
       read_poses([](auto& p) { return io::read_matrix_poses(p); })},
      {"graph", "graph.txt", "v0 0 0 0 0 0 0 1\n", "v0 0 0 0 0 0 0 1\nv1 0 0", 2, "v0 nan 0 0 0 0 0 1\n",
       "v0 inf 0 0 0 0 0 1\n", read_poses([](auto& p) { return io::read_graph_poses(p); })},
  };
  for (const PoseFormat& f : pose_formats) {
    const auto add = [&](std::string problem_case, std::string content, InputProblem expected, std::string where,
                         std::string message) {
      rows.push_back({f.name, std::move(problem_case), f.file_name, std::move(content), f.read, expected, std::move(where),
                      std::move(message)});
    };
    add("truncated", f.truncated, InputProblem::kTruncated, line(f.truncated_line), "");
    add("NaN value", f.nan, InputProblem::kNonFinite, line(1), "not finite");
    add("inf value", f.infinite, InputProblem::kNonFinite, line(1), "not finite");
    add("empty file", "", InputProblem::kEmpty, "", "");
    add("binary garbage", garbage(), InputProblem::kMalformed, line(1), "");
  }
  rows.push_back({"graph", "duplicate scans", "graph.txt", "v0 0 0 0 0 0 0 1\nv0 0 0 0 0 0 0 1\n",
                  read_poses([](auto& p) { return io::read_graph_poses(p); }), InputProblem::kInconsistentSurvey, line(2),
                  "v0 appears twice"});
  rows.push_back({"graph", "gap in numbering", "graph.txt", "v0 0 0 0 0 0 0 1\nv2 0 0 0 0 0 0 1\n",
                  read_poses([](auto& p) { return io::read_graph_poses(p); }), InputProblem::kInconsistentSurvey, line(2),
                  "no vertex v1"});
  return rows;
}

TEST(BadInput, EveryReaderGivesTheTablesKindOfErrorNamingFileAndPlace) {
  TempDir dir;
  const std::vector<Row> rows = reader_rows();
  ASSERT_GE(rows.size(), 80u);
  for (const Row& row : rows) {
    SCOPED_TRACE(row.reader + " / " + row.problem_case);
    const fs::path path = dir / row.file_name;
    write_text(path, row.content);
    try {
      row.read(path, row.settings);
      ADD_FAILURE() << "no error";
    } catch (const InputError& error) {
      const std::string what = error.what();
      EXPECT_EQ(error.problem(), row.expected) << to_string(error.problem()) << ": " << what;
      EXPECT_EQ(what.rfind(path.string() + row.where, 0), 0u) << "expected '" << path.string() + row.where << "' in: " << what;
      if (row.where.empty()) {  // no place given: the message must still not be a bare path
        EXPECT_GT(what.size(), path.string().size() + 2) << what;
      }
      EXPECT_NE(what.find(row.message), std::string::npos) << "missing '" << row.message << "' in: " << what;
    } catch (const std::exception& error) {
      ADD_FAILURE() << "not an InputError: " << error.what();
    }
  }
}

TEST(BadInput, ExitCodesAreDistinctPerProblem) {
  const std::vector<InputProblem> problems{InputProblem::kMalformed,          InputProblem::kTruncated,
                                           InputProblem::kNonFinite,          InputProblem::kEmpty,
                                           InputProblem::kInconsistentSurvey, InputProblem::kCountBeyondLimits,
                                           InputProblem::kSuspiciousUnits};
  const std::vector<int> expected{3, 7, 8, 9, 10, 11, 12};
  for (std::size_t i = 0; i < problems.size(); ++i) {
    EXPECT_EQ(static_cast<int>(exit_code_for(problems[i])), expected[i]) << to_string(problems[i]);
  }
  // The default kind of an InputError is "malformed" (exit 3), as before the kinds existed.
  EXPECT_EQ(InputError(FileLocation{"f"}, "m").problem(), InputProblem::kMalformed);
}

TEST(BadInput, NaNPointsAreDroppedAndCountedAndOnePointScansRead) {
  TempDir dir;
  std::vector<Xyz> with_nan = kGood;
  with_nan[2][2] = kNaN;
  for (const PointFormat& f : point_formats()) {
    SCOPED_TRACE(f.name);
    const fs::path path = dir / f.file_name;
    write_text(path, f.encode(with_nan));
    io::ReadReport report;
    io::ReadSettings settings;
    settings.report = &report;
    ASSERT_NO_THROW(f.read(path, settings));
    EXPECT_EQ(report.nan_points_dropped, 1u);
    // A file of one point is a valid file; the survey refuses it (CLI rows below).
    write_text(path, f.encode({{1, 2, 3}}));
    EXPECT_NO_THROW(f.read(path, {}));
  }
}

// ---- `minemap map` end to end --------------------------------------------------------------------

/// A seeded 3-scan simulated survey (uos, cm, with truth/), written once and copied per row.
const fs::path& simulated_survey() {
  static TempDir dir("minemap-bad-input-survey");
  static const bool written = [] {
    sim::SimulationSettings settings;
    settings.mine.scans = 3;
    settings.mine.seed = 7;
    const sim::SimulatedSurvey survey = sim::simulate_mine_survey(settings);
    io::write_uos_survey(dir.path(), survey.scans, survey.truth_cm);
    return true;
  }();
  (void)written;
  return dir.path();
}

std::vector<std::string> folder_names(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) names.push_back(entry.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

/// Replaces line `n` (1-based) of a text file.
void replace_line(const fs::path& path, std::size_t n, const std::string& with) {
  const std::string text = test::read_text(path);
  std::size_t start = 0;
  for (std::size_t k = 1; k < n; ++k) start = text.find('\n', start) + 1;
  const std::size_t end = text.find('\n', start);
  write_text(path, text.substr(0, start) + with + text.substr(end));
}

struct CliRow {
  std::string name;
  std::function<void(const fs::path& survey)> spoil;  ///< turns the good survey into the bad case
  int exit_code;
  std::vector<std::string> expected;  ///< parts of the output, "%S" = the survey folder
  std::string extra_args = {};
  bool writes_outputs = false;  ///< exit 0 and 4 write the map; every other code leaves the folder
};

/// The 3-scan survey's points and poses written in metres (what a metres survey read as cm is).
void rewrite_in_metres(const fs::path& s) {
  for (const std::string stem : {"scan000", "scan001", "scan002"}) {
    const Scan scan = io::read_uos_points(s / (stem + ".3d"));
    io::write_uos_points(s / (stem + ".3d"), scan, LengthUnit::kMetre);
    const Pose pose = euler_to_pose(io::read_uos_pose(s / (stem + ".pose")));
    io::write_uos_pose(s / (stem + ".pose"), pose, LengthUnit::kMetre);
    io::write_uos_pose(s / "truth" / (stem + ".pose"), pose, LengthUnit::kMetre);
  }
}

std::vector<CliRow> cli_rows() {
  const auto remove_scan = [](const fs::path& s, const std::string& stem) {
    fs::remove(s / (stem + ".3d"));
    fs::remove(s / (stem + ".pose"));
    fs::remove(s / "truth" / (stem + ".pose"));
  };
  return {
      {"truncated scan", [](auto& s) {
         // Cut after the first value of a point line halfway through, as a copy that stopped would.
         const std::string text = test::read_text(s / "scan001.3d");
         std::size_t line_start = text.find('\n', text.size() / 2) + 1;
         while (text[line_start] == '#') line_start = text.find('\n', line_start) + 1;
         write_text(s / "scan001.3d", text.substr(0, text.find(' ', line_start)));
       }, 7, {"%S/scan001.3d:", "(truncated)"}},
      {"truncated pose file", [](auto& s) { write_text(s / "scan001.pose", "10 20 30\n0 0"); }, 7,
       {"%S/scan001.pose:2:", "ends early"}},
      {"binary garbage", [](auto& s) { write_text(s / "scan001.3d", garbage()); }, 3, {"%S/scan001.3d:"}},
      {"inf coordinate", [](auto& s) { replace_line(s / "scan001.3d", 5, "1 inf 2"); }, 8,
       {"%S/scan001.3d:5:", "'inf' is not finite"}},
      {"all points NaN", [](auto& s) { write_text(s / "scan001.3d", "nan nan nan\n1 nan 2\n"); }, 8,
       {"%S/scan001.3d:2:", "all 2 are NaN"}},
      {"NaN points dropped with a warning", [](auto& s) {
         replace_line(s / "scan001.3d", 5, "nan nan nan");
         replace_line(s / "scan001.3d", 9, "1 nan 2");
       }, 0, {"warning: dropped 2 points with a NaN coordinate", "scan001.3d (2)"}, "", true},
      {"empty scan", [](auto& s) { write_text(s / "scan001.3d", ""); }, 9, {"%S/scan001.3d:", "no points (empty file)"}},
      {"scan of one point", [](auto& s) { write_text(s / "scan001.3d", "100 20 300\n"); }, 9,
       {"%S/scan001.3d:", "only 1 point"}},
      {"empty survey folder", [](auto& s) {
         for (const auto& name : folder_names(s)) fs::remove_all(s / name);
       }, 9, {"%S:", "no scans found"}},
      {"duplicate scans (a copied file)", [](auto& s) {
         fs::copy_file(s / "scan000.3d", s / "scan002.3d", fs::copy_options::overwrite_existing);
       }, 10, {"%S/scan002.3d:", "same", "scan000.3d"}},
      {"duplicate scan numbers", [](auto& s) { fs::copy_file(s / "scan001.3d", s / "scan0001.3d"); }, 10,
       {"same scan number"}},
      {"missing pose file", [](auto& s) { fs::remove(s / "scan002.pose"); }, 10, {"%S/scan002.pose:", "missing"}},
      {"missing initial poses file", [](auto&) {}, 10, {"%S/initial.tum:", "missing"},
       "--initial-poses %S/initial.tum"},
      {"initial poses for fewer scans", [](auto& s) { write_text(s / "initial.tum", "0 0 0 0 0 0 0 1\n"); }, 10,
       {"%S/initial.tum:", "has 1 poses, the survey has 3 scans"}, "--initial-poses %S/initial.tum"},
      {"gap in numbering: a warning", [=](auto& s) { remove_scan(s, "scan001"); }, 0,
       {"warning: the scan numbering has gaps: no scan001"}, "", true},
      {"absurd header count", [](auto& s) {
         for (const auto& name : folder_names(s)) fs::remove_all(s / name);
         write_text(s / "a.pcd", pcd(kGood, "binary"));
         write_text(s / "b.pcd", pcd(kGood, "binary", 1'000'000'000'000));
       }, 11, {"%S/b.pcd:9:", "claims 1000000000000 points"}},
      {"metres read as cm", [](auto& s) {
         rewrite_in_metres(s);
       }, 12, {"%S/scan00", "--unit m"}},
      {"metres read as cm, one scan with a far return", [](auto& s) {
         // A mine drive in metres read as cm spans 50-200 "cm" a scan; one return 300 m out made
         // the largest scan span 300 "cm" and passed the old largest-scan test (exit 4, no overlap).
         rewrite_in_metres(s);
         write_text(s / "scan000.3d", test::read_text(s / "scan000.3d") + "300 0 2\n");
       }, 12, {"the median scan spans only", "--unit m"}},
      {"a scan whose points are all identical", [](auto& s) {
         std::string text;
         for (int i = 0; i < 200; ++i) text += "100 20 300\n";
         write_text(s / "scan001.3d", text);
       }, 9, {"%S/scan001.3d:", "all 200 points are identical"}},
      {"scans with no overlap", [](auto& s) {
         const EulerPose pose = io::read_uos_pose(s / "scan002.pose");
         Pose far = euler_to_pose(pose);
         far(0, 3) += 10000.0;  // 100 m off: no point of scan002 near any other
         io::write_uos_pose(s / "scan002.pose", far);
       }, 4, {"%S/scan002.3d: scan scan002 not registered: too few pairs", "--min-overlap-pairs sets how many",
              "nothing was written"}},
      {"survey of one scan", [=](auto& s) {
         remove_scan(s, "scan001");
         remove_scan(s, "scan002");
       }, 0, {"note: a survey of one scan"}, "", true},
  };
}

std::string with_survey(std::string text, const fs::path& survey) {
  for (std::size_t at = text.find("%S"); at != std::string::npos; at = text.find("%S")) {
    text.replace(at, 2, survey.string());
  }
  return text;
}

TEST(BadInput, MapCommandGivesEachCaseItsExitCodeAndLeavesTheOutputFolder) {
  for (const CliRow& row : cli_rows()) {
    SCOPED_TRACE(row.name);
    TempDir dir("minemap-bad-input");
    const fs::path survey = dir / "survey";
    fs::copy(simulated_survey(), survey, fs::copy_options::recursive);
    row.spoil(survey);
    const fs::path out = dir / "out";
    fs::create_directories(out);
    write_text(out / "keep.txt", "previous result");
    std::string output;
    const int code = test::run_cli("map " + survey.string() + " --out " + out.string() + " --backend cpu " +
                                       with_survey(row.extra_args, survey),
                                   &output);
    EXPECT_EQ(code, row.exit_code) << output;
    for (const std::string& part : row.expected) {
      EXPECT_NE(output.find(with_survey(part, survey)), std::string::npos)
          << "missing '" << with_survey(part, survey) << "' in: " << output;
    }
    EXPECT_EQ(test::read_text(out / "keep.txt"), "previous result");
    if (row.writes_outputs) {
      EXPECT_TRUE(fs::exists(out / "report.json")) << output;
    } else {
      EXPECT_EQ(folder_names(out), std::vector<std::string>{"keep.txt"}) << output;
    }
  }
}

TEST(BadInput, NoOverlapIsReportedPerScanAndMetresMapWithUnitM) {
  TempDir dir("minemap-bad-input");
  const fs::path survey = dir / "survey";
  fs::copy(simulated_survey(), survey, fs::copy_options::recursive);
  // The metres survey of the table maps once the unit is given.
  for (const std::string stem : {"scan000", "scan001", "scan002"}) {
    const Scan scan = io::read_uos_points(survey / (stem + ".3d"));
    io::write_uos_points(survey / (stem + ".3d"), scan, LengthUnit::kMetre);
    for (const fs::path& pose_path : {survey / (stem + ".pose"), survey / "truth" / (stem + ".pose")}) {
      io::write_uos_pose(pose_path, euler_to_pose(io::read_uos_pose(pose_path)), LengthUnit::kMetre);
    }
  }
  std::string output;
  EXPECT_EQ(test::run_cli("map " + survey.string() + " --out " + (dir / "m").string() + " --backend cpu --unit m", &output),
            0)
      << output;
  // No overlap with --write-unregistered: exit 4, and report.json names the scan not registered.
  const EulerPose pose = io::read_uos_pose(survey / "scan002.pose", LengthUnit::kMetre);
  Pose far = euler_to_pose(pose);
  far(0, 3) += 10000.0;
  io::write_uos_pose(survey / "scan002.pose", far, LengthUnit::kMetre);
  EXPECT_EQ(test::run_cli("map " + survey.string() + " --out " + (dir / "o").string() +
                              " --backend cpu --unit m --write-unregistered",
                          &output),
            4)
      << output;
  std::ifstream in(dir / "o" / "report.json");
  const auto report = nlohmann::json::parse(in);
  ASSERT_EQ(report["scans"].size(), 3u);
  EXPECT_EQ(report["scans"][2]["name"], "scan002");
  EXPECT_EQ(report["scans"][2]["registered"], false) << report["scans"][2].dump();
}

TEST(BadInput, AnOutputFolderThatCannotBeUsedIsRefusedBeforeMapping) {
  TempDir dir("minemap-bad-input");
  const fs::path survey = dir / "survey";
  fs::copy(simulated_survey(), survey, fs::copy_options::recursive);
  const std::vector<std::string> before = folder_names(survey);
  std::string output;
  // --out is the survey folder: refused, the survey untouched (no map.ply to be read as a scan).
  EXPECT_EQ(test::run_cli("map " + survey.string() + " --out " + survey.string() + " --backend cpu", &output), 5)
      << output;
  EXPECT_NE(output.find("is the survey folder"), std::string::npos) << output;
  EXPECT_EQ(folder_names(survey), before);
  // A file, or a folder under a file: exit 5 and a sentence, not the "bug" code and a raw
  // filesystem_error.
  write_text(dir / "a-file", "x");
  EXPECT_EQ(test::run_cli("map " + survey.string() + " --out " + (dir / "a-file").string(), &output), 5) << output;
  EXPECT_NE(output.find("is a file, not a folder"), std::string::npos) << output;
  EXPECT_EQ(test::run_cli("map " + survey.string() + " --out " + (dir / "a-file" / "out").string(), &output), 5)
      << output;
  EXPECT_NE(output.find("which is a file, not a folder"), std::string::npos) << output;
  EXPECT_EQ(output.find("filesystem error"), std::string::npos) << output;
}

TEST(BadInput, AnOutputFolderHoldsThisRunsScansOnly) {
  TempDir dir("minemap-bad-input");
  const fs::path survey = dir / "survey";
  fs::copy(simulated_survey(), survey, fs::copy_options::recursive);
  const fs::path out = dir / "out";
  std::string output;
  ASSERT_EQ(test::run_cli("map " + survey.string() + " --out " + out.string() + " --backend cpu --quiet", &output), 0)
      << output;
  ASSERT_TRUE(fs::exists(out / "scan002.pose"));
  write_text(out / "notes.txt", "mine");
  for (const char* ext : {".3d", ".pose"}) fs::remove(survey / (std::string("scan002") + ext));
  fs::remove(survey / "truth" / "scan002.pose");
  ASSERT_EQ(test::run_cli("map " + survey.string() + " --out " + out.string() + " --backend cpu --quiet", &output), 0)
      << output;
  // The earlier run's scan002 files are gone (3DTK's show would load them); nothing else is touched.
  EXPECT_FALSE(fs::exists(out / "scan002.pose"));
  EXPECT_FALSE(fs::exists(out / "scan002.frames"));
  EXPECT_TRUE(fs::exists(out / "scan001.frames"));
  EXPECT_EQ(test::read_text(out / "notes.txt"), "mine");
}

TEST(BadInput, AMistypedWordIsNamedWithTheNearestRealOne) {
  TempDir dir("minemap-bad-input");
  const std::string survey = simulated_survey().string(), out = (dir / "out").string();
  struct Case {
    std::string args, expected;
  };
  for (const Case& c : std::vector<Case>{
           {"mapp " + survey + " --out " + out, "unknown command 'mapp': did you mean 'map'?"},
           {"map " + survey + " --out " + out + " --max-pair-dist 50",
            "unknown option --max-pair-dist for map: did you mean --max-pair-dist-cm?"},
           {"map " + survey + " --ou\u021b " + out, "did you mean --out?"},
           {"export " + out + " --too x.ply", "unknown option --too for export: did you mean --to?"},
       }) {
    std::string output;
    EXPECT_EQ(test::run_cli(c.args, &output), 2) << c.args << "\n" << output;
    EXPECT_NE(output.find(c.expected), std::string::npos) << c.args << "\n" << output;
  }
  EXPECT_FALSE(fs::exists(dir / "out"));
}

}  // namespace
}  // namespace minemap
