// Top and side map views (see map_views.hpp). Pipeline per view: choose two orthonormal world
// directions, find the data's extent along them, lay out a frame with one scale on both axes, bin
// the points into per-pixel counts, colour them on a log ramp, then draw the trajectories and the
// annotations (border, title, legend, scale bar, axis labels) with the built-in bitmap font.
// Thread-safety: reentrant; the only parallel step (binning) uses integer atomics, so the result
// does not depend on scheduling.
#include "minemap/report/map_views.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace minemap::report {

namespace {

// ---------------------------------------------------------------------------------------------
// 5x7 bitmap font with a 2-row descender (g, j, p, q, y, comma). One string per glyph row, '#' =
// ink. Hand-drawn here so the report has no font dependency.
struct Glyph {
  char code;
  std::array<const char*, 9> rows;  ///< 7 rows of body, then 2 of descender
};

constexpr Glyph kGlyphs[] = {
    {' ', {".....", ".....", ".....", ".....", ".....", ".....", ".....", ".....", "....."}},
    {'0', {".###.", "#...#", "#..##", "#.#.#", "##..#", "#...#", ".###.", ".....", "....."}},
    {'1', {"..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###.", ".....", "....."}},
    {'2', {".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####", ".....", "....."}},
    {'3', {"#####", "...#.", "..#..", "...#.", "....#", "#...#", ".###.", ".....", "....."}},
    {'4', {"...#.", "..##.", ".#.#.", "#..#.", "#####", "...#.", "...#.", ".....", "....."}},
    {'5', {"#####", "#....", "####.", "....#", "....#", "#...#", ".###.", ".....", "....."}},
    {'6', {"..##.", ".#...", "#....", "####.", "#...#", "#...#", ".###.", ".....", "....."}},
    {'7', {"#####", "....#", "...#.", "..#..", ".#...", ".#...", ".#...", ".....", "....."}},
    {'8', {".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###.", ".....", "....."}},
    {'9', {".###.", "#...#", "#...#", ".####", "....#", "...#.", ".##..", ".....", "....."}},
    {'A', {".###.", "#...#", "#...#", "#####", "#...#", "#...#", "#...#", ".....", "....."}},
    {'B', {"####.", "#...#", "#...#", "####.", "#...#", "#...#", "####.", ".....", "....."}},
    {'C', {".###.", "#...#", "#....", "#....", "#....", "#...#", ".###.", ".....", "....."}},
    {'D', {"###..", "#..#.", "#...#", "#...#", "#...#", "#..#.", "###..", ".....", "....."}},
    {'E', {"#####", "#....", "#....", "####.", "#....", "#....", "#####", ".....", "....."}},
    {'F', {"#####", "#....", "#....", "####.", "#....", "#....", "#....", ".....", "....."}},
    {'G', {".###.", "#...#", "#....", "#.###", "#...#", "#...#", ".####", ".....", "....."}},
    {'H', {"#...#", "#...#", "#...#", "#####", "#...#", "#...#", "#...#", ".....", "....."}},
    {'I', {".###.", "..#..", "..#..", "..#..", "..#..", "..#..", ".###.", ".....", "....."}},
    {'J', {"..###", "...#.", "...#.", "...#.", "...#.", "#..#.", ".##..", ".....", "....."}},
    {'K', {"#...#", "#..#.", "#.#..", "##...", "#.#..", "#..#.", "#...#", ".....", "....."}},
    {'L', {"#....", "#....", "#....", "#....", "#....", "#....", "#####", ".....", "....."}},
    {'M', {"#...#", "##.##", "#.#.#", "#.#.#", "#...#", "#...#", "#...#", ".....", "....."}},
    {'N', {"#...#", "#...#", "##..#", "#.#.#", "#..##", "#...#", "#...#", ".....", "....."}},
    {'O', {".###.", "#...#", "#...#", "#...#", "#...#", "#...#", ".###.", ".....", "....."}},
    {'P', {"####.", "#...#", "#...#", "####.", "#....", "#....", "#....", ".....", "....."}},
    {'Q', {".###.", "#...#", "#...#", "#...#", "#.#.#", "#..#.", ".##.#", ".....", "....."}},
    {'R', {"####.", "#...#", "#...#", "####.", "#.#..", "#..#.", "#...#", ".....", "....."}},
    {'S', {".####", "#....", "#....", ".###.", "....#", "....#", "####.", ".....", "....."}},
    {'T', {"#####", "..#..", "..#..", "..#..", "..#..", "..#..", "..#..", ".....", "....."}},
    {'U', {"#...#", "#...#", "#...#", "#...#", "#...#", "#...#", ".###.", ".....", "....."}},
    {'V', {"#...#", "#...#", "#...#", "#...#", "#...#", ".#.#.", "..#..", ".....", "....."}},
    {'W', {"#...#", "#...#", "#...#", "#.#.#", "#.#.#", "#.#.#", ".#.#.", ".....", "....."}},
    {'X', {"#...#", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", "#...#", ".....", "....."}},
    {'Y', {"#...#", "#...#", ".#.#.", "..#..", "..#..", "..#..", "..#..", ".....", "....."}},
    {'Z', {"#####", "....#", "...#.", "..#..", ".#...", "#....", "#####", ".....", "....."}},
    {'a', {".....", ".....", ".###.", "....#", ".####", "#...#", ".####", ".....", "....."}},
    {'b', {"#....", "#....", "#.##.", "##..#", "#...#", "#...#", "####.", ".....", "....."}},
    {'c', {".....", ".....", ".###.", "#....", "#....", "#...#", ".###.", ".....", "....."}},
    {'d', {"....#", "....#", ".##.#", "#..##", "#...#", "#...#", ".####", ".....", "....."}},
    {'e', {".....", ".....", ".###.", "#...#", "#####", "#....", ".###.", ".....", "....."}},
    {'f', {"..##.", ".#..#", ".#...", "###..", ".#...", ".#...", ".#...", ".....", "....."}},
    {'g', {".....", ".....", ".####", "#...#", "#...#", "#...#", ".####", "....#", ".###."}},
    {'h', {"#....", "#....", "#.##.", "##..#", "#...#", "#...#", "#...#", ".....", "....."}},
    {'i', {"..#..", ".....", ".##..", "..#..", "..#..", "..#..", ".###.", ".....", "....."}},
    {'j', {"...#.", ".....", "..##.", "...#.", "...#.", "...#.", "...#.", "#..#.", ".##.."}},
    {'k', {"#....", "#....", "#..#.", "#.#..", "##...", "#.#..", "#..#.", ".....", "....."}},
    {'l', {".##..", "..#..", "..#..", "..#..", "..#..", "..#..", ".###.", ".....", "....."}},
    {'m', {".....", ".....", "##.#.", "#.#.#", "#.#.#", "#...#", "#...#", ".....", "....."}},
    {'n', {".....", ".....", "#.##.", "##..#", "#...#", "#...#", "#...#", ".....", "....."}},
    {'o', {".....", ".....", ".###.", "#...#", "#...#", "#...#", ".###.", ".....", "....."}},
    {'p', {".....", ".....", "####.", "#...#", "#...#", "#...#", "####.", "#....", "#...."}},
    {'q', {".....", ".....", ".####", "#...#", "#...#", "#...#", ".####", "....#", "....#"}},
    {'r', {".....", ".....", "#.##.", "##..#", "#....", "#....", "#....", ".....", "....."}},
    {'s', {".....", ".....", ".####", "#....", ".###.", "....#", "####.", ".....", "....."}},
    {'t', {".#...", ".#...", "###..", ".#...", ".#...", ".#..#", "..##.", ".....", "....."}},
    {'u', {".....", ".....", "#...#", "#...#", "#...#", "#..##", ".##.#", ".....", "....."}},
    {'v', {".....", ".....", "#...#", "#...#", "#...#", ".#.#.", "..#..", ".....", "....."}},
    {'w', {".....", ".....", "#...#", "#...#", "#.#.#", "#.#.#", ".#.#.", ".....", "....."}},
    {'x', {".....", ".....", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", ".....", "....."}},
    {'y', {".....", ".....", "#...#", "#...#", "#...#", "#...#", ".####", "....#", ".###."}},
    {'z', {".....", ".....", "#####", "...#.", "..#..", ".#...", "#####", ".....", "....."}},
    {'.', {".....", ".....", ".....", ".....", ".....", ".##..", ".##..", ".....", "....."}},
    {',', {".....", ".....", ".....", ".....", ".....", ".##..", ".##..", "..#..", ".#..."}},
    {'-', {".....", ".....", ".....", "#####", ".....", ".....", ".....", ".....", "....."}},
    {'+', {".....", "..#..", "..#..", "#####", "..#..", "..#..", ".....", ".....", "....."}},
    {':', {".....", ".##..", ".##..", ".....", ".##..", ".##..", ".....", ".....", "....."}},
    {'(', {"...#.", "..#..", ".#...", ".#...", ".#...", "..#..", "...#.", ".....", "....."}},
    {')', {".#...", "..#..", "...#.", "...#.", "...#.", "..#..", ".#...", ".....", "....."}},
    {'/', {".....", "....#", "...#.", "..#..", ".#...", "#....", ".....", ".....", "....."}},
    {'=', {".....", ".....", "#####", ".....", "#####", ".....", ".....", ".....", "....."}},
    {'<', {"...#.", "..#..", ".#...", "#....", ".#...", "..#..", "...#.", ".....", "....."}},
    {'>', {".#...", "..#..", "...#.", "....#", "...#.", "..#..", ".#...", ".....", "....."}},
    {'_', {".....", ".....", ".....", ".....", ".....", ".....", "#####", ".....", "....."}},
    {'%', {"##...", "##..#", "...#.", "..#..", ".#...", "#..##", "...##", ".....", "....."}},
    {'#', {".#.#.", ".#.#.", "#####", ".#.#.", "#####", ".#.#.", ".#.#.", ".....", "....."}},
    {'\'', {"..#..", "..#..", ".#...", ".....", ".....", ".....", ".....", ".....", "....."}},
    {'?', {".###.", "#...#", "....#", "...#.", "..#..", ".....", "..#..", ".....", "....."}},
};

constexpr int kGlyphWidth = 5;
constexpr int kGlyphHeight = 7;   // cap height: what layout centres on
constexpr int kGlyphRows = 9;     // including the descender
constexpr int kGlyphAdvance = 6;  // one blank column between characters

const Glyph& glyph_for(char c) {
  // A 128-entry index built once; characters outside the font fall back to '?'.
  static const std::array<const Glyph*, 128> table = [] {
    std::array<const Glyph*, 128> t{};
    const Glyph* fallback = nullptr;
    for (const Glyph& g : kGlyphs) {
      t[static_cast<unsigned char>(g.code)] = &g;
      if (g.code == '?') fallback = &g;
    }
    for (auto& entry : t) {
      if (entry == nullptr) entry = fallback;
    }
    return t;
  }();
  const auto index = static_cast<unsigned char>(c);
  return index < 128 ? *table[index] : *table[static_cast<unsigned char>('?')];
}

// ---------------------------------------------------------------------------------------------
// Pixel drawing helpers; everything clips at the image border.

void put_pixel(RgbImage& image, int x, int y, Rgb colour) {
  if (x < 0 || y < 0 || x >= image.width_px || y >= image.height_px) return;
  std::uint8_t* p = image.at(x, y);
  p[0] = colour.r;
  p[1] = colour.g;
  p[2] = colour.b;
}

void fill_rect(RgbImage& image, int x0, int y0, int w, int h, Rgb colour) {
  for (int y = y0; y < y0 + h; ++y) {
    for (int x = x0; x < x0 + w; ++x) put_pixel(image, x, y, colour);
  }
}

void fill_disk(RgbImage& image, int cx, int cy, int radius, Rgb colour) {
  for (int dy = -radius; dy <= radius; ++dy) {
    for (int dx = -radius; dx <= radius; ++dx) {
      if (dx * dx + dy * dy <= radius * radius + radius) put_pixel(image, cx + dx, cy + dy, colour);
    }
  }
}

/// Bresenham line with a square brush of half-width `half_width`; integer-only, so deterministic.
void draw_line(RgbImage& image, int x0, int y0, int x1, int y1, int half_width, Rgb colour) {
  const int dx = std::abs(x1 - x0);
  const int dy = -std::abs(y1 - y0);
  const int sx = x0 < x1 ? 1 : -1;
  const int sy = y0 < y1 ? 1 : -1;
  int err = dx + dy;
  for (;;) {
    fill_rect(image, x0 - half_width, y0 - half_width, 2 * half_width + 1, 2 * half_width + 1, colour);
    if (x0 == x1 && y0 == y1) break;
    const int e2 = 2 * err;
    if (e2 >= dy) {
      err += dy;
      x0 += sx;
    }
    if (e2 <= dx) {
      err += dx;
      y0 += sy;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Geometry.

bool finite(const Eigen::Vector3d& p) { return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()); }
bool finite(const Eigen::Vector3f& p) { return std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.z()); }

void validate(const MapViewSettings& s) {
  if (s.up_axis < 0 || s.up_axis > 2) {
    throw std::invalid_argument("map view: up_axis must be 0, 1 or 2 (got " + std::to_string(s.up_axis) + ")");
  }
  if (s.margin_px < 0) throw std::invalid_argument("map view: margin_px must not be negative");
  // Upper bounds keep a typo from allocating gigabytes.
  constexpr int kMaxSidePx = 16384;
  if (s.width_px < 2 * s.margin_px + 32 || s.width_px > kMaxSidePx) {
    throw std::invalid_argument("map view: width_px " + std::to_string(s.width_px) +
                                " leaves no plot area (needs 2*margin_px + 32 .. " + std::to_string(kMaxSidePx) + ")");
  }
  if (s.min_height_px < 2 * s.margin_px + 16 || s.max_height_px < s.min_height_px || s.max_height_px > kMaxSidePx) {
    throw std::invalid_argument(
        "map view: height range " + std::to_string(s.min_height_px) + ".." + std::to_string(s.max_height_px) +
        " is unusable (needs 2*margin_px + 16 <= min_height_px <= max_height_px <= " + std::to_string(kMaxSidePx) +
        ")");
  }
}

Eigen::Vector3d unit(int axis) { return Eigen::Vector3d::Unit(axis); }

/// Bounding box of the points along two directions, and how many were finite.
struct Extent {
  double u_min = std::numeric_limits<double>::infinity();
  double u_max = -std::numeric_limits<double>::infinity();
  double v_min = std::numeric_limits<double>::infinity();
  double v_max = -std::numeric_limits<double>::infinity();
  std::size_t count = 0;

  void add(double u, double v) {
    u_min = std::min(u_min, u);
    u_max = std::max(u_max, u);
    v_min = std::min(v_min, v);
    v_max = std::max(v_max, v);
    ++count;
  }
  void merge(const Extent& o) {
    u_min = std::min(u_min, o.u_min);
    u_max = std::max(u_max, o.u_max);
    v_min = std::min(v_min, o.v_min);
    v_max = std::max(v_max, o.v_max);
    count += o.count;
  }
};

constexpr std::size_t kGrainPoints = 1 << 16;

/// min/max are exact and order-independent, so a plain parallel_reduce is deterministic here.
Extent point_extent(std::span<const Eigen::Vector3f> points, const Eigen::Vector3d& right, const Eigen::Vector3d& up) {
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, points.size(), kGrainPoints), Extent{},
      [&](const tbb::blocked_range<std::size_t>& range, Extent e) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          if (!finite(points[i])) continue;
          const Eigen::Vector3d p = points[i].cast<double>();
          e.add(p.dot(right), p.dot(up));
        }
        return e;
      },
      [](Extent a, const Extent& b) {
        a.merge(b);
        return a;
      });
}

void add_positions(Extent& e, std::span<const Eigen::Vector3d> positions, const Eigen::Vector3d& right,
                   const Eigen::Vector3d& up) {
  for (const Eigen::Vector3d& p : positions) {
    if (finite(p)) e.add(p.dot(right), p.dot(up));
  }
}

/// The frame for data spanning `e` (points and trajectories together).
MapViewFrame layout_frame(const Extent& e, const Eigen::Vector3d& right, const Eigen::Vector3d& up,
                          const MapViewSettings& s) {
  double u_lo = 0.0, u_hi = 0.0, v_lo = 0.0, v_hi = 0.0;
  if (e.count > 0) {
    u_lo = e.u_min;
    u_hi = e.u_max;
    v_lo = e.v_min;
    v_hi = e.v_max;
  }
  // 2 % padding keeps extreme points and trajectory dots off the plot border.
  const double pad_cm = 0.02 * std::max(u_hi - u_lo, v_hi - v_lo);
  // A 1 m minimum keeps a single point (or none) from producing a zero scale.
  const double extent_u_cm = std::max(u_hi - u_lo + 2.0 * pad_cm, 100.0);
  const double extent_v_cm = std::max(v_hi - v_lo + 2.0 * pad_cm, 1e-3);

  MapViewFrame f;
  f.right_dir = right;
  f.up_dir = up;
  f.width_px = s.width_px;
  f.plot_left_px = s.margin_px;
  f.plot_top_px = s.margin_px;
  f.plot_width_px = s.width_px - 2 * s.margin_px;
  f.cm_per_px = extent_u_cm / f.plot_width_px;
  int plot_height_px = static_cast<int>(std::ceil(extent_v_cm / f.cm_per_px));
  if (plot_height_px > s.max_height_px - 2 * s.margin_px) {
    // Too tall: shrink the scale to fit the height; the width is then padded (never stretched).
    plot_height_px = s.max_height_px - 2 * s.margin_px;
    f.cm_per_px = extent_v_cm / plot_height_px;
  }
  // Too flat (a long drive seen from the side): pad vertically, same scale.
  plot_height_px = std::max(plot_height_px, s.min_height_px - 2 * s.margin_px);
  f.plot_height_px = plot_height_px;
  f.height_px = plot_height_px + 2 * s.margin_px;
  // Centre the data in the plot area.
  const double u_mid = 0.5 * (u_lo + u_hi);
  const double v_mid = 0.5 * (v_lo + v_hi);
  f.left_cm = u_mid - (f.plot_left_px + 0.5 * f.plot_width_px) * f.cm_per_px;
  f.top_cm = v_mid + (f.plot_top_px + 0.5 * f.plot_height_px) * f.cm_per_px;
  return f;
}

/// Per-pixel point counts over the plot area, TBB-parallel. Counts are integers incremented with
/// relaxed atomics: addition of integers commutes, so the result is the same for any schedule.
std::vector<std::uint32_t> bin_points(std::span<const Eigen::Vector3f> points, const MapViewFrame& f) {
  std::vector<std::uint32_t> counts(static_cast<std::size_t>(f.plot_width_px) * f.plot_height_px, 0);
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, points.size(), kGrainPoints),
      [&](const tbb::blocked_range<std::size_t>& range) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          if (!finite(points[i])) continue;
          // The frame's own mapping, so checks made with it agree with the image.
          const Eigen::Vector2i px = f.to_pixel_index(points[i].cast<double>());
          const int col = px.x() - f.plot_left_px;
          const int row = px.y() - f.plot_top_px;
          if (col < 0 || row < 0 || col >= f.plot_width_px || row >= f.plot_height_px) continue;
          std::atomic_ref<std::uint32_t> cell(counts[static_cast<std::size_t>(row) * f.plot_width_px + col]);
          cell.fetch_add(1, std::memory_order_relaxed);
        }
      });
  return counts;
}

void draw_density(RgbImage& image, const MapViewFrame& f, const std::vector<std::uint32_t>& counts) {
  std::uint32_t max_count = 0;
  for (std::uint32_t c : counts) max_count = std::max(max_count, c);
  if (max_count == 0) return;
  // Log ramp: a lone point stays visible next to walls hit thousands of times.
  const double inv_log_max = 1.0 / std::log1p(static_cast<double>(max_count));
  for (int row = 0; row < f.plot_height_px; ++row) {
    for (int col = 0; col < f.plot_width_px; ++col) {
      const std::uint32_t c = counts[static_cast<std::size_t>(row) * f.plot_width_px + col];
      if (c == 0) continue;
      const double t = std::log1p(static_cast<double>(c)) * inv_log_max;
      const auto grey = static_cast<std::uint8_t>(
          std::lround(kSparsestGrey + (static_cast<double>(kDensestGrey) - kSparsestGrey) * t));
      put_pixel(image, f.plot_left_px + col, f.plot_top_px + row, Rgb{grey, grey, grey});
    }
  }
}

void draw_trajectory(RgbImage& image, const MapViewFrame& f, std::span<const Eigen::Vector3d> positions, Rgb colour) {
  std::vector<Eigen::Vector2i> pixels;
  pixels.reserve(positions.size());
  for (const Eigen::Vector3d& p : positions) {
    if (finite(p)) pixels.push_back(f.to_pixel_index(p));
  }
  for (std::size_t i = 1; i < pixels.size(); ++i) {
    draw_line(image, pixels[i - 1].x(), pixels[i - 1].y(), pixels[i].x(), pixels[i].y(), 1, colour);
  }
  for (std::size_t i = 0; i < pixels.size(); ++i) {
    // The start gets a larger dot so the direction of travel can be read off the map.
    fill_disk(image, pixels[i].x(), pixels[i].y(), i == 0 ? 6 : 3, colour);
  }
}

/// Largest of 1, 2, 5 x 10^k cm not longer than `max_cm`.
double round_length_cm(double max_cm) {
  double best = 1.0;
  for (double decade = 1e-3; decade <= 1e9; decade *= 10.0) {
    for (double m : {1.0, 2.0, 5.0}) {
      if (m * decade <= max_cm) best = m * decade;
    }
  }
  return best;
}

std::string length_label(double length_cm) {
  char buffer[64];
  if (length_cm >= 100.0) {
    std::snprintf(buffer, sizeof(buffer), "%g m", length_cm / 100.0);
  } else {
    std::snprintf(buffer, sizeof(buffer), "%g cm", length_cm);
  }
  return buffer;
}

struct Annotation {
  std::string axes_label;  ///< e.g. "right: x   up: z"
  bool has_trajectory = false;
  bool has_reference = false;
  bool empty = false;     ///< no finite map points
  bool has_data = false;  ///< points or positions: something the scale bar measures
};

void draw_annotations(RgbImage& image, const MapViewFrame& f, const MapViewSettings& s, const Annotation& a) {
  constexpr Rgb kBorder{170, 170, 170};
  if (s.margin_px >= 1) {
    fill_rect(image, f.plot_left_px - 1, f.plot_top_px - 1, f.plot_width_px + 2, 1, kBorder);
    fill_rect(image, f.plot_left_px - 1, f.plot_top_px + f.plot_height_px, f.plot_width_px + 2, 1, kBorder);
    fill_rect(image, f.plot_left_px - 1, f.plot_top_px - 1, 1, f.plot_height_px + 2, kBorder);
    fill_rect(image, f.plot_left_px + f.plot_width_px, f.plot_top_px - 1, 1, f.plot_height_px + 2, kBorder);
  }
  if (a.empty) {
    const int scale = 2;
    const std::string message = "no map points";
    draw_text(image, f.plot_left_px + (f.plot_width_px - text_width_px(message, scale)) / 2,
              f.plot_top_px + (f.plot_height_px - kGlyphHeight * scale) / 2, message, scale, kTextRgb);
  }
  // Text lives in the margins: 2x glyphs need 18 px with descenders, 1x glyphs 9 px.
  const int scale = s.margin_px >= 28 ? 2 : 1;
  const int text_h = kGlyphHeight * scale;
  if (s.margin_px < kGlyphRows * scale + 2) return;
  const int top_text_y = (s.margin_px - text_h) / 2;
  const int bottom_mid_y = f.height_px - s.margin_px / 2;
  const int bottom_text_y = bottom_mid_y - text_h / 2;

  if (!s.title.empty()) draw_text(image, f.plot_left_px, top_text_y, s.title, scale, kTextRgb);

  // Legend, right-aligned in the top margin: a coloured dot before each label.
  int legend_x = f.plot_left_px + f.plot_width_px;
  auto legend_entry = [&](const std::string& label, Rgb colour) {
    legend_x -= text_width_px(label, scale);
    draw_text(image, legend_x, top_text_y, label, scale, kTextRgb);
    const int dot_radius = 2 * scale + 1;
    const int dot_x = legend_x - 6 - dot_radius;
    fill_disk(image, dot_x, top_text_y + text_h / 2, dot_radius, colour);
    legend_x = dot_x - dot_radius - 10 * scale;
  };
  if (a.has_reference) legend_entry("reference", kReferenceRgb);
  if (a.has_trajectory) legend_entry("trajectory", kTrajectoryRgb);
  // Axis directions, bottom right.
  draw_text(image, f.plot_left_px + f.plot_width_px - text_width_px(a.axes_label, scale), bottom_text_y, a.axes_label,
            scale, kTextRgb);
  if (!a.has_data) return;  // with nothing drawn, a scale bar would only measure the padding

  // Scale bar, bottom left: the longest round length up to a quarter of the plot width.
  const double bar_cm = round_length_cm(0.25 * f.plot_width_px * f.cm_per_px);
  const int bar_px = std::max(1, static_cast<int>(std::lround(bar_cm / f.cm_per_px)));
  const int bar_x = f.plot_left_px;
  fill_rect(image, bar_x, bottom_mid_y - 1, bar_px, 3, kTextRgb);
  fill_rect(image, bar_x, bottom_mid_y - 4, 2, 9, kTextRgb);
  fill_rect(image, bar_x + bar_px - 2, bottom_mid_y - 4, 2, 9, kTextRgb);
  draw_text(image, bar_x + bar_px + 8, bottom_text_y, length_label(bar_cm), scale, kTextRgb);
}

constexpr char kAxisNames[3] = {'x', 'y', 'z'};

MapView render(const MapViewInput& input, const MapViewSettings& s, const Eigen::Vector3d& right,
               const Eigen::Vector3d& up, std::string axes_label) {
  Extent e = point_extent(input.points_cm, right, up);
  const bool empty = e.count == 0;
  add_positions(e, input.scan_positions_cm, right, up);
  add_positions(e, input.reference_positions_cm, right, up);

  MapView view;
  view.frame = layout_frame(e, right, up, s);
  const MapViewFrame& f = view.frame;
  view.image = RgbImage(f.width_px, f.height_px, kBackgroundRgb.r, kBackgroundRgb.g, kBackgroundRgb.b);
  if (!empty) draw_density(view.image, f, bin_points(input.points_cm, f));
  // Reference first so the mapped trajectory stays on top where they overlap.
  draw_trajectory(view.image, f, input.reference_positions_cm, kReferenceRgb);
  draw_trajectory(view.image, f, input.scan_positions_cm, kTrajectoryRgb);
  Annotation a;
  a.axes_label = std::move(axes_label);
  a.has_trajectory = !input.scan_positions_cm.empty();
  a.has_reference = !input.reference_positions_cm.empty();
  a.empty = empty;
  a.has_data = e.count > 0;
  draw_annotations(view.image, f, s, a);
  return view;
}

/// Principal direction of 2D samples (largest-eigenvalue eigenvector of their covariance), or
/// nothing when they do not spread (fewer than two distinct samples).
std::optional<Eigen::Vector2d> principal_direction(const std::vector<Eigen::Vector2d>& samples) {
  if (samples.size() < 2) return std::nullopt;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& q : samples) mean += q;
  mean /= static_cast<double>(samples.size());
  double sxx = 0.0, sxy = 0.0, syy = 0.0;
  for (const auto& q : samples) {
    const Eigen::Vector2d d = q - mean;
    sxx += d.x() * d.x();
    sxy += d.x() * d.y();
    syy += d.y() * d.y();
  }
  // Below a square millimetre of spread there is no direction to speak of.
  if (sxx + syy < 1e-2 * static_cast<double>(samples.size())) return std::nullopt;
  // Closed form for a symmetric 2x2 matrix: the major axis angle.
  const double angle = 0.5 * std::atan2(2.0 * sxy, sxx - syy);
  return Eigen::Vector2d(std::cos(angle), std::sin(angle));
}

}  // namespace

Eigen::Vector2i MapViewFrame::to_pixel_index(const Eigen::Vector3d& p_cm) const {
  // Clamped before the cast: a point far outside the map (or NaN) must not overflow an int.
  auto index = [](double v) { return static_cast<int>(std::floor(v > -1e9 ? std::min(v, 1e9) : -1e9)); };
  const Eigen::Vector2d xy = to_pixel(p_cm);
  return {index(xy.x()), index(xy.y())};
}

std::pair<int, int> top_view_axes(int up_axis) {
  switch (up_axis) {
    case 0: return {1, 2};
    case 1: return {0, 2};
    case 2: return {0, 1};
    default: throw std::invalid_argument("top_view_axes: up_axis must be 0, 1 or 2");
  }
}

int text_width_px(const std::string& text, int scale) {
  if (text.empty()) return 0;
  return (static_cast<int>(text.size()) * kGlyphAdvance - 1) * scale;
}

int draw_text(RgbImage& image, int x_px, int y_px, const std::string& text, int scale, Rgb colour) {
  int x = x_px;
  for (char c : text) {
    const Glyph& g = glyph_for(c);
    for (int row = 0; row < kGlyphRows; ++row) {
      for (int col = 0; col < kGlyphWidth; ++col) {
        if (g.rows[row][col] == '#') fill_rect(image, x + col * scale, y_px + row * scale, scale, scale, colour);
      }
    }
    x += kGlyphAdvance * scale;
  }
  return text_width_px(text, scale);
}

MapView render_top_view(const MapViewInput& input, const MapViewSettings& settings) {
  validate(settings);
  const auto [right_axis, up_axis] = top_view_axes(settings.up_axis);
  const std::string label =
      std::string("top view   right: ") + kAxisNames[right_axis] + "   up: " + kAxisNames[up_axis];
  return render(input, settings, unit(right_axis), unit(up_axis), label);
}

MapView render_side_view(const MapViewInput& input, const MapViewSettings& settings) {
  validate(settings);
  const auto [a, b] = top_view_axes(settings.up_axis);
  auto horizontal = [a = a, b = b](const Eigen::Vector3d& p) { return Eigen::Vector2d(p[a], p[b]); };

  // The trajectory's main horizontal direction; without a usable trajectory, the points'.
  std::vector<Eigen::Vector2d> samples;
  for (const Eigen::Vector3d& p : input.scan_positions_cm) {
    if (finite(p)) samples.push_back(horizontal(p));
  }
  std::optional<Eigen::Vector2d> direction = principal_direction(samples);
  Eigen::Vector2d travel = Eigen::Vector2d::Zero();
  if (direction) {
    travel = samples.back() - samples.front();
  } else {
    // A fixed stride over at most ~65k points: deterministic, and plenty for a 2x2 covariance.
    samples.clear();
    const std::size_t stride = std::max<std::size_t>(1, input.points_cm.size() / 65536);
    for (std::size_t i = 0; i < input.points_cm.size(); i += stride) {
      if (finite(input.points_cm[i])) samples.push_back(horizontal(input.points_cm[i].cast<double>()));
    }
    direction = principal_direction(samples);
  }
  Eigen::Vector2d d = direction.value_or(Eigen::Vector2d::UnitX());
  // Sign: the drive runs left to right; without a drive, the larger component points positive.
  const double along = travel.dot(d);
  if (along < 0.0 || (along == 0.0 && (std::abs(d.x()) >= std::abs(d.y()) ? d.x() : d.y()) < 0.0)) d = -d;

  Eigen::Vector3d right = Eigen::Vector3d::Zero();
  right[a] = d.x();
  right[b] = d.y();
  // Components that print as zero are written as zero, so the label never reads "-0.00".
  auto printable = [](double c) { return std::abs(c) < 0.005 ? 0.0 : c; };
  char label[160];
  std::snprintf(label, sizeof(label), "side view   right: %.2f %c %+.2f %c   up: %c", printable(d.x()), kAxisNames[a],
                printable(d.y()), kAxisNames[b], kAxisNames[settings.up_axis]);
  return render(input, settings, right, unit(settings.up_axis), label);
}

MapViewFrame write_top_view_png(const std::filesystem::path& path, const MapViewInput& input,
                                const MapViewSettings& settings) {
  MapView view = render_top_view(input, settings);
  write_png_rgb8(path, view.image);
  return view.frame;
}

MapViewFrame write_side_view_png(const std::filesystem::path& path, const MapViewInput& input,
                                 const MapViewSettings& settings) {
  MapView view = render_side_view(input, settings);
  write_png_rgb8(path, view.image);
  return view.frame;
}

}  // namespace minemap::report
