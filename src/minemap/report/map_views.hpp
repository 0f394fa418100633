#pragma once
// Map images people can look at: the paper's Fig. 6 as PNGs. The top view looks down the up axis
// (for 3DTK frames, up = y, that is the x-z plane, the paper's "zx-map"); the side view shows the
// elevation against the trajectory's main horizontal direction, so a long drive is seen from the
// side ("yx-map"). Point density is drawn on a log grey ramp, the trajectory as a red polyline with
// dots at the scan positions, an optional reference trajectory (ground truth, odometry) in blue,
// plus a scale bar and axis labels in a tiny built-in bitmap font.
//
// Scale: one length per pixel on both axes, always; when the data's aspect would make the image
// too tall or too flat, the height is clamped and the plot is padded, never stretched.
//
// Empty input: with no finite map points the views are still written (a valid PNG with the message
// "no map points" and whatever trajectory there is), because a report step should leave an
// artifact that says what happened rather than abort at the end of a long run. Non-finite points
// and positions are skipped.
//
// Thread-safety: all functions are reentrant. Point binning runs TBB-parallel in the caller's
// arena with integer atomic counts, so images are bit-identical whatever the thread count.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <utility>

#include "minemap/report/png_writer.hpp"

namespace minemap::report {

struct MapViewSettings {
  int width_px = 1600;       ///< image width; the height follows the data's aspect
  int min_height_px = 200;   ///< flatter data is padded vertically up to this height
  int max_height_px = 1600;  ///< taller data is shrunk to fit and padded horizontally
  int up_axis = 1;           ///< index of the vertical axis: 1 (y) for 3DTK frames, 2 (z) for right-handed z-up
  int margin_px = 40;        ///< frame around the plot; holds the title, the scale bar and the axis labels
  std::string title;         ///< drawn top left; empty = none. Characters outside the font show as '?'
};

struct MapViewInput {
  std::span<const Eigen::Vector3f> points_cm;                    ///< world-frame map points
  std::span<const Eigen::Vector3d> scan_positions_cm;            ///< scanner positions, in scan order
  std::span<const Eigen::Vector3d> reference_positions_cm = {};  ///< optional second trajectory
};

/// Where world points land in a written image: an orthographic projection onto two orthonormal
/// world directions with one scale. Pixel (col, row) covers [col, col+1) x [row, row+1) in the
/// continuous coordinates `to_pixel` returns.
struct MapViewFrame {
  int width_px = 0;
  int height_px = 0;
  double cm_per_px = 1.0;                                ///< the same horizontally and vertically
  Eigen::Vector3d right_dir = Eigen::Vector3d::UnitX();  ///< world direction of image +column
  Eigen::Vector3d up_dir = Eigen::Vector3d::UnitY();     ///< world direction of image -row (up is up)
  double left_cm = 0.0;                                  ///< right_dir coordinate of the image's left edge
  double top_cm = 0.0;                                   ///< up_dir coordinate of the image's top edge
  int plot_left_px = 0;  ///< the plot area (inside the margins): data is drawn only here
  int plot_top_px = 0;
  int plot_width_px = 0;
  int plot_height_px = 0;

  /// Continuous pixel coordinates (x to the right, y down) of a world point.
  Eigen::Vector2d to_pixel(const Eigen::Vector3d& p_cm) const {
    // A multiply by the reciprocal, which the compiler hoists out of the binning loop.
    const double px_per_cm = 1.0 / cm_per_px;
    return {(p_cm.dot(right_dir) - left_cm) * px_per_cm, (top_cm - p_cm.dot(up_dir)) * px_per_cm};
  }
  /// The pixel a world point is binned into (may lie outside the image for points not in the input).
  Eigen::Vector2i to_pixel_index(const Eigen::Vector3d& p_cm) const;
};

/// An image together with its frame.
struct MapView {
  RgbImage image;
  MapViewFrame frame;
};

/// Colours, exposed so checks can find the trajectory in an image.
struct Rgb {
  std::uint8_t r, g, b;
  friend bool operator==(const Rgb&, const Rgb&) = default;
};
inline constexpr Rgb kBackgroundRgb{255, 255, 255};
inline constexpr Rgb kTrajectoryRgb{214, 39, 40};  ///< the mapped trajectory
inline constexpr Rgb kReferenceRgb{31, 119, 180};  ///< the optional reference trajectory
inline constexpr Rgb kTextRgb{30, 30, 30};
/// Density ramp ends: one point per pixel is light grey, the densest pixel black.
inline constexpr std::uint8_t kSparsestGrey = 185;
inline constexpr std::uint8_t kDensestGrey = 0;

/// Renders without writing. Throws std::invalid_argument for unusable settings (up_axis outside
/// 0..2, a width or height range that leaves no plot area).
MapView render_top_view(const MapViewInput& input, const MapViewSettings& settings);
MapView render_side_view(const MapViewInput& input, const MapViewSettings& settings);

/// Renders and writes an 8-bit RGB PNG atomically. Returns the frame so callers can annotate or
/// check positions. Throws as render_*, and minemap::OutputError when the file cannot be written.
MapViewFrame write_top_view_png(const std::filesystem::path& path, const MapViewInput& input,
                                const MapViewSettings& settings);
MapViewFrame write_side_view_png(const std::filesystem::path& path, const MapViewInput& input,
                                 const MapViewSettings& settings);

/// The two horizontal axes of a top view for `up_axis` (image right, image up), chosen so the view
/// is not mirrored: up 1 (3DTK, left-handed y-up) -> (x, z); up 2 (right-handed z-up) -> (x, y);
/// up 0 -> (y, z).
std::pair<int, int> top_view_axes(int up_axis);

/// Draws `text` in the built-in 5x7 font (plus a 2-row descender) with its top-left corner at
/// (x_px, y_px), each font pixel a `scale` x `scale` block; clipped at the image border. Returns
/// the width in pixels.
int draw_text(RgbImage& image, int x_px, int y_px, const std::string& text, int scale, Rgb colour);
/// Width in pixels `draw_text` would use.
int text_width_px(const std::string& text, int scale);

}  // namespace minemap::report
