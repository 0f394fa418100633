// Shared point intake of the readers: unit, frame, float range, slices, local origin (scan_builder.hpp).
#include "minemap/io/scan_builder.hpp"

#include <cmath>
#include <limits>

#include "minemap/io/slice_detection.hpp"
#include "minemap/io/text_reader.hpp"

namespace minemap::io::detail {

ScanBuilder::ScanBuilder(const std::filesystem::path& path, const ReadSettings& settings, LengthUnit default_unit)
    : path_(path),
      unit_(settings.unit.value_or(default_unit)),
      scale_to_cm_(centimetres_per(unit_)),
      right_handed_to_3dtk_(settings.right_handed_to_3dtk),
      points_per_slice_(settings.points_per_slice),
      detect_slices_(settings.detect_slices),
      max_points_(settings.max_points),
      report_(settings.report),
      wanted_(settings.attributes) {}

ScanBuilder::AddResult ScanBuilder::add(double x, double y, double z, const PointValues& values) {
  if (std::isnan(x) || std::isnan(y) || std::isnan(z)) {
    ++nan_dropped_;
    return AddResult::kOk;
  }
  if (points_cm_.size() >= max_points_) return AddResult::kTooManyPoints;
  if ((columns_ & kTime) && !std::isfinite(values.time_s)) return AddResult::kNonFiniteTime;
  const Eigen::Vector3d p_file(x, y, z);
  const auto to_cm = [&](const Eigen::Vector3d& v) -> Eigen::Vector3d {
    return right_handed_to_3dtk_ ? right_handed_to_3dtk(v, scale_to_cm_) : Eigen::Vector3d(v * scale_to_cm_);
  };
  const Eigen::Vector3d p_cm = to_cm(p_file);
  if (!p_cm.allFinite()) return AddResult::kOutOfFloatRange;  // finite metres near DBL_MAX overflow as cm
  if (!(p_cm.cwiseAbs().maxCoeff() <= kMaxPlausibleCoordinate_cm)) return AddResult::kImplausible;
  if (!origin_chosen_) {
    origin_chosen_ = true;
    if (p_cm.norm() > kAnchorDistance_cm) {
      const double grid = kLocalOriginGrid_cm / scale_to_cm_;  // 100 m in the file's unit
      anchor_file_ = (p_file / grid).array().round().matrix() * grid;
      local_origin_cm_ = to_cm(anchor_file_);
    }
  }
  const Eigen::Vector3d local = anchor_file_.isZero() ? p_cm : to_cm(p_file - anchor_file_);
  constexpr double kFloatMax = std::numeric_limits<float>::max();
  if (!(local.cwiseAbs().maxCoeff() <= kFloatMax)) return AddResult::kOutOfFloatRange;
  points_cm_.push_back(local.cast<float>());
  if (columns_ != 0) attributes_.push_back(values, columns_);
  return AddResult::kOk;
}

std::string ScanBuilder::describe(AddResult result) const {
  if (result == AddResult::kTooManyPoints) {
    return "more than " + std::to_string(max_points_) + " points (ReadSettings::max_points)";
  }
  if (result == AddResult::kImplausible) {
    return "coordinate beyond 1e10 cm (100000 km): not a point of a survey (binary garbage, or the wrong format or "
           "unit?)";
  }
  if (result == AddResult::kNonFiniteTime) return "the point's time is not a finite number";
  return "coordinate out of range: the point does not fit a float in cm";
}

std::string ScanBuilder::no_points_message() const {
  if (nan_dropped_ == 0) return "no points";
  return "no points: all " + std::to_string(nan_dropped_) + " are NaN (no-return markers)";
}

Scan ScanBuilder::finish(bool split_unmarked) {
  if (report_ != nullptr) report_->nan_points_dropped += nan_dropped_;
  Scan scan;
  scan.name = path_.stem().string();
  scan.source_path = path_.string();
  const std::size_t count = points_cm_.size();
  std::vector<std::size_t> starts = std::move(slice_starts_);
  if (starts.empty() && split_unmarked && points_per_slice_ > 0) {
    for (std::size_t start = 0; start < count; start += points_per_slice_) starts.push_back(start);
  } else if (starts.empty() && split_unmarked && detect_slices_) {
    starts = detect_slice_starts(points_cm_);
    if (report_ != nullptr) report_->slices_detected += starts.size();
  }
  if (!starts.empty()) {
    if (count > std::numeric_limits<std::uint32_t>::max()) {
      fail_in_file(path_.string(), "too many points for slice offsets (more than 2^32)");
    }
    // Points before the first marker form a slice of their own.
    if (starts.front() != 0) starts.insert(starts.begin(), 0);
    scan.slice_offsets.reserve(starts.size() + 1);
    for (const std::size_t start : starts) scan.slice_offsets.push_back(static_cast<std::uint32_t>(start));
    scan.slice_offsets.push_back(static_cast<std::uint32_t>(count));
  }
  // Growth by push_back leaves up to twice the capacity needed, and a survey holds every scan's
  // points at once. A reader that sized them well (uos counts its lines) skips the copy.
  if (points_cm_.capacity() - points_cm_.size() > points_cm_.size() / 16) points_cm_.shrink_to_fit();
  scan.points_cm = std::move(points_cm_);
  scan.attributes = std::move(attributes_);
  scan.local_origin_cm = local_origin_cm_;
  scan.recentre_if_far(kFarFromOrigin_cm);
  return scan;
}

}  // namespace minemap::io::detail
