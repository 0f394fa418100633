#pragma once
// Survey control (issue 29): known points in the mine's grid, and how the scans observe them. A
// control file is text, one record a line, '#' starts a comment:
//
//   crs 32633                         the grid's EPSG code (optional; "EPSG:32633" also reads)
//   point M1 512345.678 6712345.678 1234.567 0.005 [0.008]
//                                     name, easting, northing, height (m), sigma (m): one for all
//                                     three axes, or horizontal then vertical
//   station scan003 M1 [0.80]         the scanner of scan003 stood over mark M1, its origin this
//                                     many metres above it (vertically; 0 when left out)
//   target scan010 T4 1.234 -0.567 8.90
//                                     point T4 seen in scan010: metres, in that scan file's own
//                                     frame (3DTK's axes for uos: x right, y up, z forward)
//
// Records come in any order. Every problem is an InputError naming the file and the line: an unknown
// record, a missing or extra value, a value that is not a number (NaN and inf too), a sigma that is
// not positive, a point named twice, an observation of a point the file does not define, a crs
// that is not a number. A scan the survey does not hold is found by check_control_scans once the
// scans' names are known.
//
// Thread-safety: pure functions.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "minemap/core/units.hpp"

namespace minemap::io {

/// A known point of the grid (metres: east, north, height; right-handed, z up).
struct ControlPoint {
  std::string name;
  Eigen::Vector3d grid_m = Eigen::Vector3d::Zero();
  double sigma_horizontal_m = 0.0;  ///< one standard deviation of E and of N
  double sigma_vertical_m = 0.0;    ///< of H
  std::int64_t line = 0;            ///< where the file defines it
};

/// A scan's observation of a control point.
struct ControlObservation {
  enum class Kind { kStation, kTarget };
  Kind kind = Kind::kStation;
  std::string scan;        ///< the scan's name (Scan::name)
  std::size_t point = 0;   ///< index in ControlFile::points
  /// kStation: the scanner's origin stood this far vertically above the mark (cm).
  double instrument_height_cm = 0.0;
  /// kTarget: the point in the scan file's frame (cm; the file gives metres).
  Eigen::Vector3d in_scan_cm = Eigen::Vector3d::Zero();
  std::int64_t line = 0;
};

struct ControlFile {
  std::string path;
  std::optional<std::uint32_t> epsg;  ///< the grid's coordinate reference system, when given
  std::vector<ControlPoint> points;
  std::vector<ControlObservation> observations;
};

/// Reads a control file. InputError naming
/// the file and line for any problem (see above), and for a file with no observation.
ControlFile read_control(const std::filesystem::path& path);

/// InputError naming the control file's line of the first observation whose scan is not among
/// `scan_names` (the survey's, in order).
void check_control_scans(const ControlFile& control, std::span<const std::string> scan_names);

/// Writes a control file in read_control's format (temp file + rename): the simulator's. `comment`
/// lines go first, each behind '#'.
void write_control(const std::filesystem::path& path, const ControlFile& control,
                   std::span<const std::string> comment = {});

}  // namespace minemap::io
