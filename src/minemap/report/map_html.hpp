#pragma once
// map.html: the registered map as a 3D view a person opens from disk, with no network. One
// self-contained page: Debian's three.js r111 and its OrbitControls inlined (embedded at build time),
// the points and the per-scan figures as data in the page.
//
// The page: the map as points coloured by height, by scan or (where the scans carry it) by intensity,
// a toggle, with a colour bar for the ramps; the trajectory as a line
// with a marker at each scan position, orbit/pan/zoom, a scale bar in metres at the orbit centre,
// and an info box with a scan's name, ICP iterations, pairs, rms and doubt when its marker is
// clicked (or named in the address: map.html#scan=NAME). After its first render it sets
// document.title to "minemap map: rendered N points in T ms" (T: from navigation start); it prints
// nothing to the console unless something fails (then the title starts "minemap map: failed").
//
// Data: at most `max_points` points, chosen with a fixed fractional stride over the input order
// (so every scan keeps its share); each kept point's coordinates are quantised to uint16 per axis
// within the kept points' bounding box (a step of extent / 65535: 4 mm for a 250 m drive) and the
// scan of each point is run-length coded; little-endian, base64 in the page. 6 bytes a point,
// 8 in base64: 2 million points make a page of about 17 MB. Same input, same bytes.
//
// Axes: the page's frame is three.js's (right-handed, y up, metres). up_axis 1 (3DTK: left-handed,
// y up) maps (x, y, z) to (x, y, -z), which un-mirrors it; 2 (right-handed, z up) to (x, z, -y); 0
// (right-handed, x up) to (z, x, y).
//
// Thread-safety: reentrant. Empty input (no finite point) still writes a page (trajectory only).
#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>

#include "minemap/core/units.hpp"

namespace minemap::report {

struct MapHtmlSettings {
  std::size_t max_points = 2'000'000;  ///< points in the page at most (0: all); keeps a laptop browser smooth
  std::string title;                   ///< shown on the page and as its title
  int up_axis = 1;                     ///< the survey's vertical axis: 1 (y) for 3DTK frames, 2 (z), 0 (x)
  LengthUnit unit = LengthUnit::kCentimetre;  ///< the survey's unit: rms and positions in the info box
};

/// One scan's figures from the mapping report.
struct MapHtmlScan {
  std::string name;
  Eigen::Vector3d position_cm = Eigen::Vector3d::Zero();  ///< the scanner's world position
  int iterations = 0;                                     ///< ICP iterations of its last match
  std::size_t pairs = 0;                                  ///< pairs in that match's last iteration
  double rms_cm = 0.0;                                    ///< RMS pair distance there
  bool registered = true;                                 ///< false: the pose is the odometry's
  std::string doubt;  ///< why the match is doubtful, or why it failed when !registered; empty: neither
  std::string note;   ///< how a trusted match got there, when not plainly ("trusted after a retry from 4 m")
  /// A map tied to control: the scan's sigma in words ("1.2 x 0.8 x 0.3 cm, 0.02 deg"); empty: none.
  std::string sigma;
  /// The same scan's largest 1-sigma axis in cm (0: no sigma): the scan markers' colour.
  double sigma_cm = 0.0;
};

struct MapHtmlInput {
  std::span<const Eigen::Vector3f> points_cm;     ///< world-frame map points (non-finite ones skipped)
  std::span<const std::uint32_t> point_scans;     ///< each point's scan, an index into `scans`
  std::span<const MapHtmlScan> scans;             ///< in scan order: the trajectory
  /// Each point's intensity (as the files store it), or empty: no intensity colouring. The page
  /// holds one byte a point, the ramp spanning the kept points' 2nd to 98th percentile.
  std::span<const float> point_intensity = {};
};

/// The page's text. Throws std::invalid_argument when point_scans (or point_intensity, when given)
/// and points_cm differ in length,
/// a scan index is out of range, or up_axis is not 0..2.
std::string map_html(const MapHtmlInput& input, const MapHtmlSettings& settings);

/// Writes map_html(...) to `path` atomically. Throws as map_html, and minemap::OutputError when the
/// file cannot be written.
void write_map_html(const std::filesystem::path& path, const MapHtmlInput& input, const MapHtmlSettings& settings);

}  // namespace minemap::report
