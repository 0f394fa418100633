// map.html without a browser (tests/viewer/check_map_html.py renders it in headless Chromium): the
// page is self-contained (three.js inlined, nothing fetched), its data decodes back to the input
// points within the quantisation step, decimation caps the count and repeats, 2 million points stay
// far below 40 MB, names cannot break out of their <script>, and the file is written atomically.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "minemap/core/error.hpp"
#include "minemap/report/map_html.hpp"
#include "test_support.hpp"

namespace minemap::report {
namespace {

struct Survey {
  std::vector<Eigen::Vector3f> points_cm;
  std::vector<std::uint32_t> point_scans;
  std::vector<MapHtmlScan> scans;
  MapHtmlInput input() const { return {points_cm, point_scans, scans}; }
};

/// `scan_count` scans along x every 2 m, `points_per_scan` points in a 10 m box around each.
Survey make_survey(std::size_t scan_count, std::size_t points_per_scan) {
  Survey s;
  for (std::size_t i = 0; i < scan_count; ++i) {
    const Eigen::Vector3f at(200.0f * static_cast<float>(i), 50.0f, -30.0f);
    for (const auto& p : test::random_cloud(points_per_scan, -500.0f, 500.0f, static_cast<std::uint32_t>(i + 1))) {
      s.points_cm.push_back(at + p);
      s.point_scans.push_back(static_cast<std::uint32_t>(i));
    }
    MapHtmlScan scan;
    scan.name = "scan" + std::to_string(i);
    scan.position_cm = at.cast<double>();
    scan.iterations = 10 + static_cast<int>(i);
    scan.pairs = 1000 + i;
    scan.rms_cm = 1.5;
    s.scans.push_back(scan);
  }
  return s;
}

/// The text of the <script> element with this id.
std::string script_text(const std::string& page, const std::string& id) {
  const std::string open = "id=\"" + id + "\">";
  const std::size_t begin = page.find(open);
  if (begin == std::string::npos) return {};
  const std::size_t end = page.find("</script>", begin);
  return page.substr(begin + open.size(), end - begin - open.size());
}

std::vector<std::uint8_t> from_base64(const std::string& text) {
  std::vector<std::uint8_t> out;
  std::uint32_t bits = 0;
  int count = 0;
  for (const char c : text) {
    int v;
    if (c >= 'A' && c <= 'Z') v = c - 'A';
    else if (c >= 'a' && c <= 'z') v = c - 'a' + 26;
    else if (c >= '0' && c <= '9') v = c - '0' + 52;
    else if (c == '+') v = 62;
    else if (c == '/') v = 63;
    else break;  // '=' padding
    bits = (bits << 6) | static_cast<std::uint32_t>(v);
    if ((count += 6) >= 8) {
      count -= 8;
      out.push_back(static_cast<std::uint8_t>((bits >> count) & 0xffu));
    }
  }
  return out;
}

struct Decoded {
  nlohmann::json meta;
  std::vector<Eigen::Vector3d> points_m;  ///< in the page's frame
  std::vector<std::uint32_t> point_scans;
};

Decoded decode(const std::string& page) {
  Decoded d;
  d.meta = nlohmann::json::parse(script_text(page, "minemap-meta"));
  const auto bytes = from_base64(script_text(page, "minemap-points"));
  const std::size_t n = d.meta["points"];
  EXPECT_EQ(bytes.size(), 6 * n);
  const auto u16 = [&](std::size_t at) { return bytes[at] | (bytes[at + 1] << 8); };
  for (std::size_t i = 0; i + 1 <= n && 6 * i + 6 <= bytes.size(); ++i) {
    Eigen::Vector3d p;
    for (int axis = 0; axis < 3; ++axis) {
      p[axis] = d.meta["min_m"][axis].get<double>() + d.meta["step_m"][axis].get<double>() * u16(6 * i + 2 * axis);
    }
    d.points_m.push_back(p);
  }
  const auto runs = from_base64(script_text(page, "minemap-runs"));
  const auto u32 = [&](std::size_t at) {
    return static_cast<std::uint32_t>(runs[at] | (runs[at + 1] << 8) | (runs[at + 2] << 16)) |
           (static_cast<std::uint32_t>(runs[at + 3]) << 24);
  };
  for (std::size_t r = 0; r + 8 <= runs.size(); r += 8) d.point_scans.insert(d.point_scans.end(), u32(r + 4), u32(r));
  return d;
}

std::size_t count_of(const std::string& text, const std::string& needle) {
  std::size_t count = 0;
  for (std::size_t at = text.find(needle); at != std::string::npos; at = text.find(needle, at + 1)) ++count;
  return count;
}

TEST(MapHtml, IsSelfContainedWithThreeJsInlined) {
  const Survey s = make_survey(3, 500);
  std::string page = map_html(s.input(), MapHtmlSettings{});
  // The library's own files, whole (they name http URLs in comments and XML namespaces: not fetches).
  for (const char* file : {MINEMAP_THREE_JS, MINEMAP_THREE_ORBIT_CONTROLS_JS}) {
    const std::string library = test::read_text(file);
    ASSERT_GT(library.size(), 10'000u) << file;
    const std::size_t at = page.find(library);
    ASSERT_NE(at, std::string::npos) << file << " is not inlined";
    page.erase(at, library.size());
  }
  EXPECT_NE(page.find("THREE.OrbitControls"), std::string::npos);
  for (const char* external : {"http://", "https://", "src=", "href=", "<link", "url(", "import ", "fetch(", "XMLHttpRequest"}) {
    EXPECT_EQ(page.find(external), std::string::npos) << external;
  }
}

TEST(MapHtml, PointsDecodeWithinTheQuantisationStepInThePageFrame) {
  const Survey s = make_survey(4, 300);
  for (const int up_axis : {0, 1, 2}) {
    MapHtmlSettings settings;
    settings.up_axis = up_axis;
    const Decoded d = decode(map_html(s.input(), settings));
    ASSERT_EQ(d.points_m.size(), s.points_cm.size());
    EXPECT_EQ(d.point_scans, s.point_scans);
    Eigen::Vector3d tolerance_m;  // half a quantisation step, plus rounding
    for (int axis = 0; axis < 3; ++axis) tolerance_m[axis] = 0.5 * d.meta["step_m"][axis].get<double>() + 1e-9;
    for (std::size_t i = 0; i < s.points_cm.size(); ++i) {
      const Eigen::Vector3d p = s.points_cm[i].cast<double>() / 100.0;
      // three.js's frame: y up, right-handed. 3DTK (y up) is left-handed: z flips.
      const Eigen::Vector3d expected = up_axis == 1 ? Eigen::Vector3d(p.x(), p.y(), -p.z())
                                       : up_axis == 2 ? Eigen::Vector3d(p.x(), p.z(), -p.y())
                                                      : Eigen::Vector3d(p.z(), p.x(), p.y());
      ASSERT_TRUE(((d.points_m[i] - expected).cwiseAbs().array() <= tolerance_m.array()).all())
          << "up " << up_axis << " point " << i << ": " << d.points_m[i].transpose() << " for " << expected.transpose();
    }
  }
}

TEST(MapHtml, ScanFiguresAreInTheSurveyUnit) {
  Survey s = make_survey(2, 10);
  s.scans[1].registered = false;
  s.scans[1].doubt = "too few pairs";
  MapHtmlSettings settings;
  settings.unit = LengthUnit::kMetre;
  const Decoded d = decode(map_html(s.input(), settings));
  EXPECT_EQ(d.meta["unit"], "m");
  ASSERT_EQ(d.meta["scans"].size(), 2u);
  const auto& scan = d.meta["scans"][1];
  EXPECT_EQ(scan["name"], "scan1");
  EXPECT_EQ(scan["iterations"], 11);
  EXPECT_EQ(scan["pairs"], 1001);
  EXPECT_DOUBLE_EQ(scan["rms"].get<double>(), 0.015);
  EXPECT_DOUBLE_EQ(scan["at"][0].get<double>(), 2.0);
  EXPECT_FALSE(scan["registered"].get<bool>());
  EXPECT_EQ(scan["doubt"], "too few pairs");
  EXPECT_EQ(d.meta["scans"][0]["note"], "");
}

TEST(MapHtml, ATrustedScanSaysItNeededTheRetry) {
  Survey s = make_survey(2, 10);
  s.scans[1].note = "trusted after a retry from 400 cm";
  const Decoded d = decode(map_html(s.input(), {}));
  EXPECT_EQ(d.meta["scans"][1]["note"], "trusted after a retry from 400 cm");
  EXPECT_EQ(d.meta["scans"][1]["doubt"], "");
}

TEST(MapHtml, DecimationCapsThePointsKeepsEveryScanAndRepeats) {
  const Survey s = make_survey(10, 1000);
  MapHtmlSettings settings;
  settings.max_points = 1234;
  const std::string page = map_html(s.input(), settings);
  const Decoded d = decode(page);
  EXPECT_EQ(d.meta["points"], 1234);
  EXPECT_EQ(d.meta["points_in"], 10000);
  ASSERT_EQ(d.point_scans.size(), 1234u);
  for (std::uint32_t scan = 0; scan < 10; ++scan) {  // a fixed stride: each scan keeps its share
    const auto kept = std::count(d.point_scans.begin(), d.point_scans.end(), scan);
    EXPECT_NEAR(static_cast<double>(kept), 123.4, 1.0) << scan;
  }
  EXPECT_EQ(map_html(s.input(), settings), page);
  settings.max_points = 0;  // no cap
  EXPECT_EQ(decode(map_html(s.input(), settings)).meta["points"], 10000);
}

TEST(MapHtml, TwoMillionPointsStayWellUnder40MB) {
  // 200 scans of 15 000 points: a 200-scan survey's map, capped at the default 2 million.
  const Survey s = make_survey(200, 15'000);
  const std::string page = map_html(s.input(), MapHtmlSettings{});
  const Decoded d = decode(page);
  EXPECT_EQ(d.meta["points"], 2'000'000);
  EXPECT_LT(page.size(), 20'000'000u);  // 8 base64 bytes a point, three.js 0.9 MB
  EXPECT_GT(page.size(), 16'000'000u);
}

TEST(MapHtml, NonFinitePointsAreSkippedAndAnEmptyMapStillMakesAPage) {
  Survey s = make_survey(2, 100);
  s.points_cm[5] = Eigen::Vector3f(std::nanf(""), 0.0f, 0.0f);
  s.points_cm[7].z() = std::numeric_limits<float>::infinity();
  EXPECT_EQ(decode(map_html(s.input(), MapHtmlSettings{})).meta["points"], 198);

  const Survey empty = make_survey(1, 0);
  const std::string page = map_html(empty.input(), MapHtmlSettings{});
  EXPECT_EQ(decode(page).meta["points"], 0);
  EXPECT_EQ(decode(page).meta["scans"].size(), 1u);
}

TEST(MapHtml, NamesAndTitleCannotLeaveTheirElements) {
  Survey s = make_survey(2, 10);
  s.scans[0].name = "</script><script>alert(1)</script><!--";
  MapHtmlSettings settings;
  settings.title = "<b>mine</b> & \"drive\"";
  const std::string page = map_html(s.input(), settings);
  EXPECT_EQ(count_of(page, "</script>"), 6u);  // meta, points, runs, three.js, OrbitControls, viewer
  EXPECT_EQ(page.find("<b>mine"), std::string::npos);
  EXPECT_NE(page.find("<title>&lt;b&gt;mine&lt;/b&gt; &amp; &quot;drive&quot;</title>"), std::string::npos);
  EXPECT_EQ(decode(page).meta["scans"][0]["name"], s.scans[0].name);  // the JSON still reads back the same
}

TEST(MapHtml, RejectsInconsistentInput) {
  Survey s = make_survey(2, 10);
  s.point_scans.pop_back();
  EXPECT_THROW(map_html(s.input(), MapHtmlSettings{}), std::invalid_argument);
  s = make_survey(2, 10);
  s.point_scans[3] = 2;  // no such scan
  EXPECT_THROW(map_html(s.input(), MapHtmlSettings{}), std::invalid_argument);
  s = make_survey(2, 10);
  MapHtmlSettings settings;
  settings.up_axis = 3;
  EXPECT_THROW(map_html(s.input(), settings), std::invalid_argument);
}

TEST(MapHtml, IsWrittenAtomically) {
  const Survey s = make_survey(3, 100);
  test::TempDir dir;
  const auto target = dir / "map.html";
  test::write_text(target, "old");
  write_map_html(target, s.input(), MapHtmlSettings{});
  EXPECT_EQ(test::read_text(target), map_html(s.input(), MapHtmlSettings{}));
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().filename(), "map.html") << "left behind: " << entry.path();
  }
}

TEST(MapHtml, UnwritablePathThrowsOutputErrorAndLeavesNoFile) {
  const Survey s = make_survey(1, 10);
  test::TempDir dir;
  const auto target = dir.path() / "missing_folder" / "map.html";
  EXPECT_THROW(write_map_html(target, s.input(), MapHtmlSettings{}), OutputError);
  EXPECT_FALSE(std::filesystem::exists(target));
}

}  // namespace
}  // namespace minemap::report
