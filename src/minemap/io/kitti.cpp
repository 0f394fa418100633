// KITTI Velodyne .bin: raw little-endian float32 records, x y z intensity (4 floats, KITTI's own
// files) or x y z (3 floats, e.g. gtsam_points' kitti_07_dump points.bin). No header, so the file size
// alone says how many points there are; the 4th float is kept as the intensity (Scan::attributes).
#include <cmath>
#include <stdexcept>
#include <string>
#include <system_error>

#include "minemap/core/atomic_file.hpp"
#include "minemap/io/binary_data.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/io/scan_builder.hpp"
#include "minemap/io/text_reader.hpp"

namespace minemap::io {
namespace {

void require_supported_layout(int floats_per_point) {
  if (floats_per_point != 3 && floats_per_point != 4) {
    throw std::invalid_argument("KITTI .bin: floats_per_point must be 3 or 4, not " + std::to_string(floats_per_point));
  }
}

}  // namespace

Scan read_kitti_bin(const fs::path& path, const ReadSettings& settings, int floats_per_point) {
  require_supported_layout(floats_per_point);
  const std::string name = path.string();
  const std::uint64_t record_bytes = 4 * static_cast<std::uint64_t>(floats_per_point);
  // The size alone gives the point count: check it against max_points before reading the file.
  std::error_code error;
  const std::uintmax_t size_on_disk = fs::file_size(path, error);
  if (!error && size_on_disk / record_bytes > settings.max_points) {
    detail::fail_in_file(name,
                         "holds " + std::to_string(size_on_disk / record_bytes) + " points, more than max_points = " +
                             std::to_string(settings.max_points),
                         InputProblem::kCountBeyondLimits);
  }
  const detail::ScanFileBytes file(path);
  const std::string& bytes = file.bytes();
  if (bytes.empty()) detail::fail_at_byte(name, 0, "no points (empty file)", InputProblem::kEmpty);
  const std::uint64_t whole_records = bytes.size() / record_bytes;
  // A common variant writes x y z only (3 floats) under KITTI's NNNNNN.bin name. Its size may not
  // divide by 16 (then it looked truncated), or may (then every 4th float, taken for a reflectance,
  // is a coordinate). Refuse it either way with what it is.
  const std::string three_floats_hint =
      ": a file of 3 float32 per point (x y z)? KITTI's NNNNNN.bin holds 4 (x y z reflectance); minemap reads a "
      "3-float file as NNNNNN/points.bin (a folder per scan)";
  if (floats_per_point == 4 && bytes.size() % 16 != 0 && bytes.size() % 12 == 0) {
    detail::fail_in_file(name, "file size " + std::to_string(bytes.size()) + " is a multiple of 12 bytes, not of 16" +
                                   three_floats_hint);
  }
  if (floats_per_point == 4 && bytes.size() % 12 == 0) {
    for (std::uint64_t i = 0; i < whole_records; ++i) {
      const float reflectance = detail::load_le<float>(bytes.data() + i * 16 + 12);
      if (!(reflectance >= 0.0f) || std::isinf(reflectance)) {
        detail::fail_at_byte(name, i * 16 + 12,
                             "point " + std::to_string(i) + ": its 4th float, " + std::to_string(reflectance) +
                                 ", is no reflectance (never negative or infinite)" + three_floats_hint);
      }
    }
  }
  if (bytes.size() % record_bytes != 0) {
    detail::fail_at_byte(name, whole_records * record_bytes,
                         "file size " + std::to_string(bytes.size()) + " is not a multiple of " +
                             std::to_string(record_bytes) + " bytes (" + std::to_string(floats_per_point) +
                             " float32 per point): the last point is truncated",
                         InputProblem::kTruncated);
  }
  if (whole_records > settings.max_points) {
    detail::fail_in_file(name,
                         "holds " + std::to_string(whole_records) + " points, more than max_points = " +
                             std::to_string(settings.max_points),
                         InputProblem::kCountBeyondLimits);
  }
  detail::ScanBuilder builder(path, settings, LengthUnit::kMetre);
  if (floats_per_point == 4) builder.carries(kIntensity);  // KITTI's 4th float, the reflectance
  builder.reserve(static_cast<std::size_t>(whole_records));
  for (std::uint64_t i = 0; i < whole_records; ++i) {
    const std::uint64_t offset = i * record_bytes;
    const char* record = bytes.data() + offset;
    const double x = detail::load_le<float>(record);
    const double y = detail::load_le<float>(record + 4);
    const double z = detail::load_le<float>(record + 8);
    const double xyz[3] = {x, y, z};
    for (int axis = 0; axis < 3; ++axis) {
      if (std::isinf(xyz[axis])) {  // NaN drops the point (ScanBuilder)
        detail::fail_at_byte(name, offset + 4 * static_cast<std::uint64_t>(axis),
                             "point " + std::to_string(i) + ": " + static_cast<char>('x' + axis) + " is not finite",
                             InputProblem::kNonFinite);
      }
    }
    PointValues values;
    if (floats_per_point == 4) values.intensity = detail::load_le<float>(record + 12);
    const auto added = builder.add(x, y, z, values);
    if (added != detail::ScanBuilder::AddResult::kOk) {
      detail::fail_at_byte(name, offset, "point " + std::to_string(i) + ": " + builder.describe(added),
                           builder.problem_of(added));
    }
  }
  if (builder.size() == 0) detail::fail_at_byte(name, 0, builder.no_points_message(), builder.no_points_problem());
  return builder.finish(/*split_unmarked=*/false);
}

void write_kitti_bin(const fs::path& path, const Scan& scan, int floats_per_point, LengthUnit unit) {
  require_supported_layout(floats_per_point);
  const double divisor = centimetres_per(unit);
  std::string out;
  out.reserve(scan.size() * 4 * static_cast<std::size_t>(floats_per_point));
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const Eigen::Vector3d p = scan.file_point(i) / divisor;
    for (int axis = 0; axis < 3; ++axis) detail::append_le(out, static_cast<float>(p[axis]));
    if (floats_per_point == 4) {
      detail::append_le(out, scan.attributes.intensity.empty() ? 0.0f : scan.attributes.intensity[i]);
    }
  }
  write_file_atomically(path, out);
}

}  // namespace minemap::io
