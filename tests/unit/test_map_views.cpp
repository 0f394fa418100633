// Map views: a synthetic L-shaped corridor (3DTK frame, y up) whose second leg climbs 4 m, with a
// trajectory down its centre line. The PNGs are read back and checked against the known geometry:
// where the walls and the empty inside of the L land, where the scan positions land, which way up
// the ramp goes, that both axes have one scale, that bytes repeat, and that a z-up frame works.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <vector>

#include "minemap/core/error.hpp"
#include "minemap/report/map_views.hpp"
#include "minemap/report/png_writer.hpp"
#include "test_support.hpp"

namespace minemap::report {
namespace {

constexpr double kLegALengthCm = 3000.0;  // along +z from z = 0
constexpr double kLegBEndXCm = 2000.0;    // leg B runs along +x at z = 3000
constexpr double kHalfWidthCm = 150.0;
constexpr double kHeightCm = 250.0;
constexpr double kClimbCm = 400.0;  // leg B's floor rises this much towards its end

double floor_y_cm(double x_cm, double z_cm) {
  if (z_cm < kLegALengthCm - kHalfWidthCm) return 0.0;
  const double t = std::clamp((x_cm - kHalfWidthCm) / (kLegBEndXCm - kHalfWidthCm), 0.0, 1.0);
  return kClimbCm * t;
}

struct Corridor {
  std::vector<Eigen::Vector3f> points_cm;
  std::vector<Eigen::Vector3d> scans_cm;
  std::vector<Eigen::Vector3d> reference_cm;
};

/// Walls, floor and ceiling sampled every 10 cm; scans every 2 m, 80 cm above the floor.
Corridor make_corridor() {
  Corridor c;
  constexpr double step = 10.0;
  auto column = [&](double x, double z) {  // a vertical line of wall points
    const double y0 = floor_y_cm(x, z);
    for (double y = y0; y <= y0 + kHeightCm; y += step) c.points_cm.emplace_back(x, y, z);
  };
  auto floor_and_ceiling = [&](double x, double z) {
    const double y0 = floor_y_cm(x, z);
    c.points_cm.emplace_back(x, y0, z);
    c.points_cm.emplace_back(x, y0 + kHeightCm, z);
  };
  // Leg A: walls at x = +-150; the inner wall stops where leg B opens, the outer one closes the corner.
  for (double z = 0; z <= kLegALengthCm + kHalfWidthCm; z += step) {
    column(-kHalfWidthCm, z);
    if (z <= kLegALengthCm - kHalfWidthCm) column(kHalfWidthCm, z);
    for (double x = -kHalfWidthCm + step; x < kHalfWidthCm; x += step) floor_and_ceiling(x, z);
  }
  // Leg B: walls at z = 3000 +- 150.
  for (double x = kHalfWidthCm; x <= kLegBEndXCm; x += step) {
    column(x, kLegALengthCm - kHalfWidthCm);
    column(x, kLegALengthCm + kHalfWidthCm);
    for (double z = kLegALengthCm - kHalfWidthCm + step; z < kLegALengthCm + kHalfWidthCm; z += step) {
      floor_and_ceiling(x, z);
    }
  }
  for (double z = 0; z <= kLegALengthCm; z += 200.0) c.scans_cm.emplace_back(0.0, 80.0, z);
  for (double x = 200; x <= kLegBEndXCm - 100.0; x += 200.0) {
    c.scans_cm.emplace_back(x, floor_y_cm(x, kLegALengthCm) + 80.0, kLegALengthCm);
  }
  // A drifting "odometry": off by 20 cm more in x at every scan.
  for (std::size_t i = 0; i < c.scans_cm.size(); ++i) {
    c.reference_cm.push_back(c.scans_cm[i] + Eigen::Vector3d(20.0 * static_cast<double>(i), 0.0, 0.0));
  }
  return c;
}

MapViewInput input_of(const Corridor& c, bool with_reference = false) {
  MapViewInput in;
  in.points_cm = c.points_cm;
  in.scan_positions_cm = c.scans_cm;
  if (with_reference) in.reference_positions_cm = c.reference_cm;
  return in;
}

Rgb pixel(const RgbImage& image, int x, int y) {
  const std::uint8_t* p = image.at(x, y);
  return {p[0], p[1], p[2]};
}

Rgb pixel(const RgbImage& image, const Eigen::Vector2i& xy) { return pixel(image, xy.x(), xy.y()); }

bool is_background(Rgb c) { return c == kBackgroundRgb; }
/// A density pixel: grey (r = g = b) on the ramp.
bool is_point_grey(Rgb c) { return c.r == c.g && c.g == c.b && c.r <= kSparsestGrey; }

/// Bounding box (inclusive) of density pixels inside the plot area.
struct PixelBox {
  int x_min = std::numeric_limits<int>::max(), x_max = -1;
  int y_min = std::numeric_limits<int>::max(), y_max = -1;
};

PixelBox grey_box(const RgbImage& image, const MapViewFrame& f) {
  PixelBox box;
  for (int y = f.plot_top_px; y < f.plot_top_px + f.plot_height_px; ++y) {
    for (int x = f.plot_left_px; x < f.plot_left_px + f.plot_width_px; ++x) {
      if (!is_point_grey(pixel(image, x, y))) continue;
      box.x_min = std::min(box.x_min, x);
      box.x_max = std::max(box.x_max, x);
      box.y_min = std::min(box.y_min, y);
      box.y_max = std::max(box.y_max, y);
    }
  }
  return box;
}

/// Copies the written views to $MINEMAP_MAP_VIEWS_DUMP_DIR, for looking at them by eye.
void maybe_dump(const std::filesystem::path& file) {
  if (const char* dir = std::getenv("MINEMAP_MAP_VIEWS_DUMP_DIR")) {
    std::filesystem::create_directories(dir);
    std::filesystem::copy_file(file, std::filesystem::path(dir) / file.filename(),
                               std::filesystem::copy_options::overwrite_existing);
  }
}

TEST(MapViews, TopViewShowsCorridorWhereItIsAndNothingElsewhere) {
  const Corridor c = make_corridor();
  test::TempDir dir;
  MapViewSettings s;
  s.title = "synthetic L corridor";
  const MapViewFrame f = write_top_view_png(dir / "top.png", input_of(c, true), s);
  maybe_dump(dir / "top.png");
  const RgbImage image = read_png_rgb8(dir / "top.png");

  ASSERT_EQ(image.width_px, 1600);
  ASSERT_EQ(image.height_px, f.height_px);
  EXPECT_EQ(f.width_px, 1600);
  // The L is 31.5 m deep but 21.5 m wide: too tall for 1600 px at the width's scale, so the height
  // is clamped and the sides padded.
  EXPECT_EQ(f.height_px, s.max_height_px);
  EXPECT_EQ(f.right_dir, Eigen::Vector3d::UnitX());
  EXPECT_EQ(f.up_dir, Eigen::Vector3d::UnitZ());

  // Corridor floor (off the centre line, where the trajectory runs) is grey in both legs.
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(100, 0, 1500), Eigen::Vector3d(-100, 0, 500),
                                   Eigen::Vector3d(1200, 0, 3100), Eigen::Vector3d(1800, 0, 2900)}) {
    EXPECT_TRUE(is_point_grey(pixel(image, f.to_pixel_index(p)))) << p.transpose();
  }
  // Inside the L's corner and beyond its ends there is nothing.
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(1000, 0, 1000), Eigen::Vector3d(1800, 0, 300),
                                   Eigen::Vector3d(-140, 0, -50), Eigen::Vector3d(1000, 0, 2700)}) {
    const Eigen::Vector2i px = f.to_pixel_index(p);
    ASSERT_GE(px.x(), f.plot_left_px);
    ASSERT_LT(px.y(), f.plot_top_px + f.plot_height_px);
    EXPECT_TRUE(is_background(pixel(image, px))) << p.transpose();
  }
  // Up in the image is +z: the far end of leg A is near the top, the start near the bottom.
  EXPECT_LT(f.to_pixel(Eigen::Vector3d(0, 0, 3000)).y(), f.to_pixel(Eigen::Vector3d(0, 0, 0)).y());
  EXPECT_LT(f.to_pixel(Eigen::Vector3d(-150, 0, 0)).x(), f.to_pixel(Eigen::Vector3d(2000, 0, 0)).x());
  // Every scan position is drawn in the trajectory colour.
  for (const Eigen::Vector3d& p : c.scans_cm) {
    EXPECT_EQ(pixel(image, f.to_pixel_index(p)), kTrajectoryRgb) << p.transpose();
  }
  // The drifting reference has its own colour where it has left the mapped trajectory.
  EXPECT_EQ(pixel(image, f.to_pixel_index(c.reference_cm.back())), kReferenceRgb);
}

TEST(MapViews, TopViewHasOneScaleOnBothAxes) {
  const Corridor c = make_corridor();
  test::TempDir dir;
  MapViewSettings s;
  s.max_height_px = 4000;  // room for the natural aspect: no padding on either axis
  const MapViewFrame f = write_top_view_png(dir / "top.png", input_of(c), s);
  const RgbImage image = read_png_rgb8(dir / "top.png");
  const PixelBox box = grey_box(image, f);
  // The grey extent in pixels times one cm_per_px gives back the corridor's size on both axes.
  const double width_cm = (box.x_max - box.x_min + 1) * f.cm_per_px;
  const double depth_cm = (box.y_max - box.y_min + 1) * f.cm_per_px;
  EXPECT_NEAR(width_cm, kLegBEndXCm + kHalfWidthCm, 2.0 * f.cm_per_px);
  EXPECT_NEAR(depth_cm, kLegALengthCm + kHalfWidthCm, 2.0 * f.cm_per_px);
  EXPECT_GT(f.height_px, 1600);  // followed the data's aspect
  EXPECT_LT(f.height_px, 4000);
}

TEST(MapViews, SideViewShowsTheClimbWithUpUp) {
  const Corridor c = make_corridor();
  test::TempDir dir;
  MapViewSettings s;
  s.title = "side";
  const MapViewFrame f = write_side_view_png(dir / "side.png", input_of(c, true), s);
  maybe_dump(dir / "side.png");
  const RgbImage image = read_png_rgb8(dir / "side.png");
  ASSERT_EQ(image.width_px, f.width_px);
  ASSERT_EQ(image.height_px, f.height_px);

  // The view direction is horizontal and follows the drive (start on the left, end on the right).
  EXPECT_NEAR(f.right_dir.norm(), 1.0, 1e-12);
  EXPECT_EQ(f.right_dir.y(), 0.0);
  EXPECT_EQ(f.up_dir, Eigen::Vector3d::UnitY());
  EXPECT_GT((c.scans_cm.back() - c.scans_cm.front()).dot(f.right_dir), 0.0);

  // Read the climb off the pixels alone: the highest grey row near the right end of the map must
  // be above the highest near the left end, by the climb at this scale.
  const PixelBox box = grey_box(image, f);
  auto top_grey_row = [&](int x0, int x1) {
    int top = std::numeric_limits<int>::max();
    for (int x = x0; x <= x1; ++x) {
      for (int y = f.plot_top_px; y < f.plot_top_px + f.plot_height_px; ++y) {
        if (is_point_grey(pixel(image, x, y))) {
          top = std::min(top, y);
          break;
        }
      }
    }
    return top;
  };
  const int band = (box.x_max - box.x_min) / 20;
  const int left_top = top_grey_row(box.x_min, box.x_min + band);
  const int right_top = top_grey_row(box.x_max - band, box.x_max);
  EXPECT_LT(right_top, left_top);
  EXPECT_NEAR((left_top - right_top) * f.cm_per_px, kClimbCm, 4.0 * f.cm_per_px);

  // One scale: the grey height is the corridor height plus the climb, the grey width the points'
  // extent along the view direction.
  double along_min = std::numeric_limits<double>::infinity(), along_max = -along_min;
  for (const auto& p : c.points_cm) {
    const double u = p.cast<double>().dot(f.right_dir);
    along_min = std::min(along_min, u);
    along_max = std::max(along_max, u);
  }
  EXPECT_NEAR((box.y_max - box.y_min + 1) * f.cm_per_px, kHeightCm + kClimbCm, 2.0 * f.cm_per_px);
  EXPECT_NEAR((box.x_max - box.x_min + 1) * f.cm_per_px, along_max - along_min, 2.0 * f.cm_per_px);

  for (const Eigen::Vector3d& p : c.scans_cm) {
    EXPECT_EQ(pixel(image, f.to_pixel_index(p)), kTrajectoryRgb) << p.transpose();
  }
}

TEST(MapViews, FlatLongDriveIsPaddedNotStretched) {
  // 100 m of straight, level tunnel 2.5 m high: far too flat for its width, so the height is the
  // minimum and the tunnel keeps its true thickness in pixels.
  std::vector<Eigen::Vector3f> points;
  for (double x = 0; x <= 10000; x += 10) {
    for (double y = 0; y <= 250; y += 10) points.emplace_back(x, y, 0.0f);
  }
  std::vector<Eigen::Vector3d> scans;
  for (double x = 0; x <= 10000; x += 500) scans.emplace_back(x, 80, 0);
  MapViewInput in;
  in.points_cm = points;
  in.scan_positions_cm = scans;
  MapViewSettings s;
  const MapView view = render_side_view(in, s);
  EXPECT_EQ(view.frame.height_px, s.min_height_px);
  EXPECT_EQ(view.frame.right_dir, Eigen::Vector3d::UnitX());
  const PixelBox box = grey_box(view.image, view.frame);
  EXPECT_NEAR((box.y_max - box.y_min + 1) * view.frame.cm_per_px, 250.0, 2.0 * view.frame.cm_per_px);
  EXPECT_NEAR((box.x_max - box.x_min + 1) * view.frame.cm_per_px, 10000.0, 2.0 * view.frame.cm_per_px);
}

TEST(MapViews, BytesRepeatWhateverTheThreadCount) {
  const Corridor c = make_corridor();
  test::TempDir dir;
  MapViewSettings s;
  s.title = "determinism";
  // Enough points that the binning is split over many TBB chunks.
  std::vector<Eigen::Vector3f> many;
  for (int copy = 0; copy < 8; ++copy) many.insert(many.end(), c.points_cm.begin(), c.points_cm.end());
  MapViewInput in = input_of(c, true);
  in.points_cm = many;
  write_top_view_png(dir / "a_top.png", in, s);
  write_side_view_png(dir / "a_side.png", in, s);
  tbb::task_arena single(1);
  single.execute([&] {
    write_top_view_png(dir / "b_top.png", in, s);
    write_side_view_png(dir / "b_side.png", in, s);
  });
  write_top_view_png(dir / "c_top.png", in, s);
  EXPECT_EQ(test::read_text(dir / "a_top.png"), test::read_text(dir / "b_top.png"));
  EXPECT_EQ(test::read_text(dir / "a_top.png"), test::read_text(dir / "c_top.png"));
  EXPECT_EQ(test::read_text(dir / "a_side.png"), test::read_text(dir / "b_side.png"));
}

TEST(MapViews, ZUpFrameGivesTheSameMap) {
  // The same corridor in a right-handed z-up frame: swap y and z (the 3DTK -> right-handed
  // reflection). Top view (x right, y up) and side view must show the same pixels; only the axis
  // label in the bottom margin differs.
  const Corridor c = make_corridor();
  Corridor r;
  for (const auto& p : c.points_cm) r.points_cm.emplace_back(p.x(), p.z(), p.y());
  for (const auto& p : c.scans_cm) r.scans_cm.emplace_back(p.x(), p.z(), p.y());
  MapViewSettings s;
  s.title = "frame";
  MapViewSettings s_zup = s;
  s_zup.up_axis = 2;

  for (const bool side : {false, true}) {
    const MapView a = side ? render_side_view(input_of(c), s) : render_top_view(input_of(c), s);
    const MapView b = side ? render_side_view(input_of(r), s_zup) : render_top_view(input_of(r), s_zup);
    ASSERT_EQ(a.frame.width_px, b.frame.width_px);
    ASSERT_EQ(a.frame.height_px, b.frame.height_px);
    EXPECT_DOUBLE_EQ(a.frame.cm_per_px, b.frame.cm_per_px);
    EXPECT_EQ(b.frame.up_dir, side ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitY());
    const std::size_t above_bottom_margin =
        static_cast<std::size_t>(a.frame.height_px - s.margin_px) * a.frame.width_px * 3;
    EXPECT_TRUE(std::equal(a.image.rgb.begin(), a.image.rgb.begin() + static_cast<std::ptrdiff_t>(above_bottom_margin),
                           b.image.rgb.begin()))
        << (side ? "side" : "top");
  }
  // And the z-up top view is a proper map: +y (the corridor's depth) points up in the image.
  const MapView top = render_top_view(input_of(r), s_zup);
  EXPECT_LT(top.frame.to_pixel(Eigen::Vector3d(0, 3000, 0)).y(), top.frame.to_pixel(Eigen::Vector3d(0, 0, 0)).y());
  for (const Eigen::Vector3d& p : r.scans_cm) EXPECT_EQ(pixel(top.image, top.frame.to_pixel_index(p)), kTrajectoryRgb);
}

TEST(MapViews, NonFinitePointsAreSkipped) {
  const Corridor c = make_corridor();
  std::vector<Eigen::Vector3f> with_nan = c.points_cm;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  with_nan.insert(with_nan.begin() + 100, Eigen::Vector3f(nan, 0, 0));
  with_nan.emplace_back(0, inf, 0);
  with_nan.emplace_back(1e3f, 0, -inf);
  std::vector<Eigen::Vector3d> scans_with_nan = c.scans_cm;
  scans_with_nan.emplace_back(std::nan(""), 0, 0);
  MapViewInput clean = input_of(c);
  MapViewInput dirty = clean;
  dirty.points_cm = with_nan;
  dirty.scan_positions_cm = scans_with_nan;
  const MapViewSettings s;
  EXPECT_EQ(render_top_view(clean, s).image.rgb, render_top_view(dirty, s).image.rgb);
  EXPECT_EQ(render_side_view(clean, s).image.rgb, render_side_view(dirty, s).image.rgb);
}

TEST(MapViews, EmptyInputStillWritesAValidImage) {
  test::TempDir dir;
  const MapViewSettings s;
  // Nothing at all (or only NaNs): a small image with the message "no map points".
  const std::vector<Eigen::Vector3f> only_nan{Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN())};
  MapViewInput nothing;
  nothing.points_cm = only_nan;
  for (const bool side : {false, true}) {
    const auto file = dir / (side ? "empty_side.png" : "empty_top.png");
    const MapViewFrame f = side ? write_side_view_png(file, nothing, s) : write_top_view_png(file, nothing, s);
    maybe_dump(file);
    const RgbImage image = read_png_rgb8(file);
    EXPECT_EQ(image.width_px, s.width_px);
    EXPECT_EQ(image.height_px, f.height_px);
    EXPECT_GE(image.height_px, s.min_height_px);
    // The message is drawn in the plot area's middle row band.
    bool has_text = false;
    const int mid = f.plot_top_px + f.plot_height_px / 2;
    for (int y = mid - 7; y <= mid + 7 && !has_text; ++y) {
      for (int x = f.plot_left_px; x < f.plot_left_px + f.plot_width_px; ++x) {
        if (pixel(image, x, y) == kTextRgb) {
          has_text = true;
          break;
        }
      }
    }
    EXPECT_TRUE(has_text);
  }
  // No points but a trajectory: the trajectory is still drawn.
  const Corridor c = make_corridor();
  MapViewInput only_trajectory;
  only_trajectory.scan_positions_cm = c.scans_cm;
  const MapView view = render_top_view(only_trajectory, s);
  for (const auto& p : c.scans_cm) EXPECT_EQ(pixel(view.image, view.frame.to_pixel_index(p)), kTrajectoryRgb);
}

TEST(MapViews, SinglePointAndSinglePositionDoNotDivideByZero) {
  const std::vector<Eigen::Vector3f> one_point{Eigen::Vector3f(5, 6, 7)};
  const std::vector<Eigen::Vector3d> one_scan{Eigen::Vector3d(5, 6, 7)};
  MapViewInput in;
  in.points_cm = one_point;
  in.scan_positions_cm = one_scan;
  for (const bool side : {false, true}) {
    const MapView view = side ? render_side_view(in, MapViewSettings{}) : render_top_view(in, MapViewSettings{});
    EXPECT_TRUE(std::isfinite(view.frame.cm_per_px));
    EXPECT_GT(view.frame.cm_per_px, 0.0);
    EXPECT_EQ(pixel(view.image, view.frame.to_pixel_index(one_scan[0])), kTrajectoryRgb);
  }
}

TEST(MapViews, RejectsUnusableSettings) {
  const Corridor c = make_corridor();
  MapViewSettings s;
  s.up_axis = 3;
  EXPECT_THROW(render_top_view(input_of(c), s), std::invalid_argument);
  s = MapViewSettings{};
  s.width_px = 60;  // narrower than the margins
  EXPECT_THROW(render_side_view(input_of(c), s), std::invalid_argument);
  s = MapViewSettings{};
  s.min_height_px = 2000;  // above max_height_px
  EXPECT_THROW(render_top_view(input_of(c), s), std::invalid_argument);
}

TEST(MapViews, UnwritablePathThrowsOutputErrorAndLeavesNoFile) {
  const Corridor c = make_corridor();
  test::TempDir dir;
  const auto target = dir.path() / "missing_folder" / "top.png";
  EXPECT_THROW(write_top_view_png(target, input_of(c), MapViewSettings{}), OutputError);
  EXPECT_FALSE(std::filesystem::exists(target));
}

TEST(MapViews, AnnotationsAreDrawnInTheMargins) {
  const Corridor c = make_corridor();
  MapViewSettings s;
  s.title = "title";
  const MapView view = render_top_view(input_of(c, true), s);
  auto count_text = [&](int y0, int y1) {
    int n = 0;
    for (int y = y0; y < y1; ++y) {
      for (int x = 0; x < view.image.width_px; ++x) n += pixel(view.image, x, y) == kTextRgb ? 1 : 0;
    }
    return n;
  };
  EXPECT_GT(count_text(0, s.margin_px - 1), 50);                                             // title
  EXPECT_GT(count_text(view.frame.height_px - s.margin_px + 1, view.frame.height_px), 200);  // scale bar, axes
  // The legend dots carry both trajectory colours.
  int trajectory_dots = 0, reference_dots = 0;
  for (int y = 0; y < s.margin_px - 1; ++y) {
    for (int x = 0; x < view.image.width_px; ++x) {
      trajectory_dots += pixel(view.image, x, y) == kTrajectoryRgb ? 1 : 0;
      reference_dots += pixel(view.image, x, y) == kReferenceRgb ? 1 : 0;
    }
  }
  EXPECT_GT(trajectory_dots, 10);
  EXPECT_GT(reference_dots, 10);
}

TEST(BitmapFont, DrawsKnownGlyphsAndFallsBackToQuestionMark) {
  RgbImage a(40, 20, 255, 255, 255);
  RgbImage b(40, 20, 255, 255, 255);
  EXPECT_EQ(draw_text(a, 1, 1, "~", 1, kTextRgb), 5);
  draw_text(b, 1, 1, "?", 1, kTextRgb);
  EXPECT_EQ(a.rgb, b.rgb);
  EXPECT_EQ(text_width_px("10 m", 2), (4 * 6 - 1) * 2);
  RgbImage c(40, 20, 255, 255, 255);
  draw_text(c, 0, 0, "1", 1, kTextRgb);
  // '1' has its stem in column 2 on every row from the second to the last.
  for (int y = 1; y < 7; ++y) EXPECT_EQ(pixel(c, 2, y), kTextRgb) << y;
  EXPECT_EQ(pixel(c, 0, 0), kBackgroundRgb);
  // Clipped, not crashing, at the border.
  draw_text(c, 38, 18, "Wm", 3, kTextRgb);
}

TEST(PngWriter, RoundTripsPixelsAndRejectsBadBuffers) {
  RgbImage image(17, 9, 0, 0, 0);
  for (std::size_t i = 0; i < image.rgb.size(); ++i) image.rgb[i] = static_cast<std::uint8_t>((i * 37) % 251);
  const std::vector<std::uint8_t> bytes = encode_png_rgb8(image);
  ASSERT_GT(bytes.size(), 8u);
  EXPECT_EQ(bytes[1], 'P');
  const RgbImage back = decode_png_rgb8(bytes);
  EXPECT_EQ(back.width_px, 17);
  EXPECT_EQ(back.height_px, 9);
  EXPECT_EQ(back.rgb, image.rgb);
  EXPECT_EQ(encode_png_rgb8(image), bytes);

  RgbImage broken = image;
  broken.rgb.pop_back();
  EXPECT_THROW(encode_png_rgb8(broken), std::invalid_argument);
  const std::vector<std::uint8_t> garbage{1, 2, 3, 4, 5};
  EXPECT_THROW(decode_png_rgb8(garbage), std::runtime_error);
}

}  // namespace
}  // namespace minemap::report
