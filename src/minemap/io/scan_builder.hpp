#pragma once
// Internal to src/minemap/io: turns points as a file stores them (its unit, maybe a right-handed
// frame) into a Scan (cm, 3DTK frame, float relative to a local origin). Every point reader feeds it,
// so unit conversion, the change of frame and float-range checks exist once.
//
// Far clouds: when the first point lies more than kAnchorDistance_cm (1 km) from the file's origin,
// where a float in cm has steps of 0.01 cm and more, points are stored relative to that point's
// position rounded to kLocalOriginGrid_cm (100 m: within 87 m of it, so float steps stay below
// 0.001 cm; the grid makes a copy moved by whole hundreds of metres read to the same floats), so a
// cloud in UTM coordinates keeps float resolution (converting to float first
// and recentring afterwards would already have lost it). finish() then calls Scan::recentre_if_far,
// which moves the origin to the centroid when that lies more than 100 m away. A cloud around the
// file's origin (within 1 km) keeps origin zero unless its centroid is more than 100 m out.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "minemap/core/error.hpp"
#include "minemap/core/scan.hpp"
#include "minemap/io/formats.hpp"

namespace minemap::io::detail {

/// Scan::recentre_if_far's threshold: centroids farther out become the local origin.
inline constexpr double kFarFromOrigin_cm = 10000.0;
/// A first point farther out than this anchors the points before they are converted to float.
inline constexpr double kAnchorDistance_cm = 100000.0;
/// No coordinate of a real survey lies farther out (10^5 km; Earth-centred coordinates stay below
/// 10^4 km). Binary garbage read as float32 does, about 4 values in 10.
inline constexpr double kMaxPlausibleCoordinate_cm = 1e10;

class ScanBuilder {
 public:
  enum class AddResult {
    kOk,               ///< added, or dropped as a NaN point (counted, see nan_dropped())
    kTooManyPoints,    ///< more than ReadSettings::max_points
    kOutOfFloatRange,  ///< the point, relative to the local origin, does not fit a float
    kImplausible,      ///< a coordinate beyond kMaxPlausibleCoordinate_cm
    kNonFiniteTime     ///< a point's time (kept) is inf or NaN: its sweep could not be deskewed
  };

  ScanBuilder(const std::filesystem::path& path, const ReadSettings& settings, LengthUnit default_unit);

  LengthUnit unit() const { return unit_; }
  std::uint64_t max_points() const { return max_points_; }
  std::size_t size() const { return points_cm_.size(); }
  void reserve(std::size_t count) {
    points_cm_.reserve(count);
    if (columns_ & kIntensity) attributes_.intensity.reserve(count);
    if (columns_ & kColour) attributes_.rgb.reserve(count);
    if (columns_ & kTime) attributes_.time_s.reserve(count);
    if (columns_ & kRing) attributes_.ring.reserve(count);
    if (columns_ & kReturnNumber) attributes_.return_number.reserve(count);
  }

  /// The attributes the file carries (PointAttribute bits); the scan keeps those of them that
  /// ReadSettings::attributes asks for. Call before the first add.
  void carries(std::uint8_t columns) { columns_ = columns & wanted_; }
  /// The attributes kept: what add's `values` must hold.
  std::uint8_t columns() const { return columns_; }

  /// Adds a point given in the file's unit and frame, with its attribute values (those of columns()).
  /// A point with a NaN coordinate is dropped and counted, its values with it; callers refuse
  /// infinite values first, as only they know the line or byte to report.
  [[nodiscard]] AddResult add(double x, double y, double z, const PointValues& values = {});

  /// Points dropped because a coordinate was NaN.
  std::uint64_t nan_dropped() const { return nan_dropped_; }

  /// Message and kind for a file that gave no point: all NaN (kNonFinite) or none at all (kEmpty).
  std::string no_points_message() const;
  InputProblem no_points_problem() const {
    return nan_dropped_ > 0 ? InputProblem::kNonFinite : InputProblem::kEmpty;
  }

  /// Marks the start of a slice at the current point (uos "# slice N" markers).
  void begin_slice() { slice_starts_.push_back(points_cm_.size()); }

  /// The scan, named after the file's stem. Slices come from begin_slice() markers, else from
  /// ReadSettings::points_per_slice when `split_unmarked` is set, else from the points' order
  /// (ReadSettings::detect_slices, io/slice_detection.hpp), else there are none.
  Scan finish(bool split_unmarked);

  /// Message and kind for a failed add(), for the caller to throw at its location.
  std::string describe(AddResult result) const;
  static InputProblem problem_of(AddResult result) {
    if (result == AddResult::kTooManyPoints) return InputProblem::kCountBeyondLimits;
    return result == AddResult::kNonFiniteTime ? InputProblem::kNonFinite : InputProblem::kMalformed;
  }

 private:
  std::filesystem::path path_;
  LengthUnit unit_;
  double scale_to_cm_;
  bool right_handed_to_3dtk_;
  std::uint32_t points_per_slice_;
  bool detect_slices_;
  std::uint64_t max_points_;
  ReadReport* report_;
  std::uint64_t nan_dropped_ = 0;
  bool origin_chosen_ = false;
  Eigen::Vector3d local_origin_cm_ = Eigen::Vector3d::Zero();
  /// local_origin_cm_ in the file's frame and unit: subtracted before the unit's scale, so a file
  /// whose coordinates are the original's plus whole hundreds of metres gives the original's
  /// numbers exactly (scaling first rounds the sum, and the original's bits with it).
  Eigen::Vector3d anchor_file_ = Eigen::Vector3d::Zero();
  std::vector<Eigen::Vector3f> points_cm_;
  std::uint8_t wanted_ = kAllPointAttributes;
  std::uint8_t columns_ = 0;
  PointAttributes attributes_;
  std::vector<std::size_t> slice_starts_;
};

}  // namespace minemap::io::detail
