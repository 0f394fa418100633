// Trajectory files: 4x4 matrices, TUM, KITTI 3x4 and gtsam_points graphs, plus the rigid-pose checks
// every pose-reading format shares (pose_text.hpp). All of them allow '#' comments and blank lines, and
// values separated by commas as well as whitespace (4x4 matrices written as CSV).
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "minemap/core/atomic_file.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/io/pose_text.hpp"
#include "minemap/io/text_reader.hpp"
#include "minemap/io/text_writer.hpp"

namespace minemap::io {

namespace detail {

Pose checked_rigid_pose(const Pose& raw, const LineReader& reader) {
  if (!raw.allFinite()) reader.fail("pose has a value out of range", InputProblem::kNonFinite);
  const Eigen::Matrix3d rotation = raw.block<3, 3>(0, 0);
  const double orthonormality_error = (rotation * rotation.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (!(orthonormality_error <= kRotationTolerance)) {
    std::string message = "rotation is not orthonormal (R R^T differs from I by ";
    append_number(message, orthonormality_error);
    reader.fail(message + ")");
  }
  if (rotation.determinant() < 0) reader.fail("rotation is a reflection (determinant -1)");
  const double last_row_error =
      std::abs(raw(3, 0)) + std::abs(raw(3, 1)) + std::abs(raw(3, 2)) + std::abs(raw(3, 3) - 1.0);
  if (!(last_row_error <= kRotationTolerance)) reader.fail("last row of the matrix is not 0 0 0 1");
  return orthonormalised(raw);
}

Pose pose_from_quaternion(const Eigen::Vector3d& translation_cm, double qw, double qx, double qy, double qz,
                          const LineReader& reader) {
  Eigen::Quaterniond q(qw, qx, qy, qz);
  const double norm = q.norm();
  if (!(std::abs(norm - 1.0) <= kRotationTolerance)) {
    std::string message = "quaternion is not unit length (norm ";
    append_number(message, norm);
    reader.fail(message + ")");
  }
  if (!translation_cm.allFinite()) reader.fail("translation out of range", InputProblem::kNonFinite);
  q.normalize();
  Pose pose = Pose::Identity();
  pose.block<3, 3>(0, 0) = q.toRotationMatrix();
  pose.block<3, 1>(0, 3) = translation_cm;
  return pose;
}

}  // namespace detail

namespace {

using detail::LineReader;

/// The most values a trajectory line may hold (a 4x4 matrix on one line); longer lines are counted.
constexpr std::size_t kMaxLineValues = 16;
using LineTokens = std::array<std::string_view, kMaxLineValues>;

/// Calls on_line(tokens, count) for every line with data ('#' comments stripped, blanks skipped).
template <class OnLine>
void for_each_data_line(LineReader& reader, OnLine&& on_line) {
  LineTokens tokens;
  std::string_view line;
  while (reader.next(line)) {
    const std::string_view content = detail::strip_comment(line);
    if (detail::is_blank(content)) continue;
    on_line(tokens, detail::split_tokens(content, tokens, /*commas=*/true));
  }
}

void require_value_count(const LineReader& reader, std::size_t count, std::size_t expected, std::string_view layout) {
  if (count != expected) {
    const std::string problem =
        "expected " + std::to_string(expected) + " values (" + std::string(layout) + "), found " + std::to_string(count);
    if (count < expected) reader.fail_short_line(problem);
    reader.fail(problem);
  }
}

template <class T>
void require_some(const std::vector<T>& poses, const LineReader& reader) {
  if (poses.empty()) detail::fail_at_line(reader.path(), reader.line_number(), "no poses", InputProblem::kEmpty);
}

void append_row(std::string& out, std::span<const double> values) {
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (i > 0) out += ' ';
    detail::append_number(out, values[i]);
  }
  out += '\n';
}

/// Translation x y z and quaternion x y z w (TUM and graph order) of a pose, translation in `unit`.
std::array<double, 7> translation_and_quaternion(const Pose& pose_cm, LengthUnit unit) {
  const double divisor = centimetres_per(unit);
  Eigen::Quaterniond q(Eigen::Matrix3d(pose_cm.block<3, 3>(0, 0)));
  q.normalize();
  return {pose_cm(0, 3) / divisor, pose_cm(1, 3) / divisor, pose_cm(2, 3) / divisor, q.x(), q.y(), q.z(), q.w()};
}

/// A graph line's vertex name "vK"; false if the token is not one.
bool parse_vertex_name(std::string_view token, std::uint64_t& index) {
  return token.size() >= 2 && token.front() == 'v' && detail::parse_uint64(token.substr(1), index) &&
         token[1] != '+';
}

}  // namespace

std::vector<Pose> read_matrix_poses(const fs::path& path, LengthUnit unit) {
  const std::string text = detail::read_file_bytes(path);
  LineReader reader(text, path.string());
  const double scale_to_cm = centimetres_per(unit);
  std::vector<Pose> poses;
  Pose raw = Pose::Identity();
  int rows_read = 0;  // rows of the matrix in progress: each matrix is 4 lines of 4, or 1 line of 16
  std::array<double, 16> values{};
  const auto finish_matrix = [&] {
    raw.block<3, 1>(0, 3) *= scale_to_cm;
    poses.push_back(detail::checked_rigid_pose(raw, reader));
    rows_read = 0;
  };
  for_each_data_line(reader, [&](const LineTokens& tokens, std::size_t count) {
    if (count == 16 && rows_read == 0) {
      detail::parse_finite_values(reader, tokens, values, "matrix");
      for (int i = 0; i < 16; ++i) raw(i / 4, i % 4) = values[static_cast<std::size_t>(i)];
      finish_matrix();
      return;
    }
    require_value_count(reader, count, 4, "a row of a 4x4 matrix, row-major");
    detail::parse_finite_values(reader, std::span(tokens).first(4), std::span(values).first(4), "matrix");
    for (int col = 0; col < 4; ++col) raw(rows_read, col) = values[static_cast<std::size_t>(col)];
    if (++rows_read == 4) finish_matrix();
  });
  if (rows_read != 0) {
    detail::fail_at_line(path.string(), reader.line_number(),
                         "file ends inside a matrix (" + std::to_string(rows_read) + " of 4 rows)",
                         InputProblem::kTruncated);
  }
  require_some(poses, reader);
  return poses;
}

void write_matrix_poses(const fs::path& path, std::span<const Pose> poses_cm, LengthUnit unit) {
  const double divisor = centimetres_per(unit);
  std::string out;
  for (std::size_t k = 0; k < poses_cm.size(); ++k) {
    if (k > 0) out += '\n';  // a blank line between matrices
    for (int row = 0; row < 4; ++row) {
      std::array<double, 4> values{};
      for (int col = 0; col < 4; ++col) values[static_cast<std::size_t>(col)] = poses_cm[k](row, col);
      if (row < 3) values[3] /= divisor;
      append_row(out, values);
    }
  }
  write_file_atomically(path, out);
}

std::vector<TimedPose> read_tum(const fs::path& path, LengthUnit unit) {
  const std::string text = detail::read_file_bytes(path);
  LineReader reader(text, path.string());
  const double scale_to_cm = centimetres_per(unit);
  std::vector<TimedPose> poses;
  std::array<double, 8> values{};
  for_each_data_line(reader, [&](const LineTokens& tokens, std::size_t count) {
    require_value_count(reader, count, 8, "TUM: timestamp tx ty tz qx qy qz qw");
    detail::parse_finite_values(reader, std::span(tokens).first(8), values, "TUM");
    const Eigen::Vector3d translation_cm = Eigen::Vector3d(values[1], values[2], values[3]) * scale_to_cm;
    poses.push_back(TimedPose{values[0], detail::pose_from_quaternion(translation_cm, values[7], values[4], values[5],
                                                                      values[6], reader)});
  });
  require_some(poses, reader);
  return poses;
}

void write_tum(const fs::path& path, std::span<const TimedPose> poses, LengthUnit unit) {
  std::string out = "# timestamp tx ty tz qx qy qz qw\n";
  for (const TimedPose& timed : poses) {
    const auto tq = translation_and_quaternion(timed.pose_cm, unit);
    std::array<double, 8> values{};
    values[0] = timed.timestamp_s;
    std::copy(tq.begin(), tq.end(), values.begin() + 1);
    append_row(out, values);
  }
  write_file_atomically(path, out);
}

std::vector<Pose> read_kitti_poses(const fs::path& path, LengthUnit unit) {
  const std::string text = detail::read_file_bytes(path);
  LineReader reader(text, path.string());
  const double scale_to_cm = centimetres_per(unit);
  std::vector<Pose> poses;
  std::array<double, 12> values{};
  for_each_data_line(reader, [&](const LineTokens& tokens, std::size_t count) {
    require_value_count(reader, count, 12, "KITTI: a 3x4 matrix, row-major");
    detail::parse_finite_values(reader, std::span(tokens).first(12), values, "KITTI");
    Pose raw = Pose::Identity();
    for (int i = 0; i < 12; ++i) raw(i / 4, i % 4) = values[static_cast<std::size_t>(i)];
    raw.block<3, 1>(0, 3) *= scale_to_cm;
    poses.push_back(detail::checked_rigid_pose(raw, reader));
  });
  require_some(poses, reader);
  return poses;
}

void write_kitti_poses(const fs::path& path, std::span<const Pose> poses_cm, LengthUnit unit) {
  const double divisor = centimetres_per(unit);
  std::string out;
  for (const Pose& pose : poses_cm) {
    std::array<double, 12> values{};
    for (int i = 0; i < 12; ++i) values[static_cast<std::size_t>(i)] = pose(i / 4, i % 4);
    for (int row = 0; row < 3; ++row) values[static_cast<std::size_t>(row * 4 + 3)] /= divisor;
    append_row(out, values);
  }
  write_file_atomically(path, out);
}

std::vector<Pose> read_graph_poses(const fs::path& path, LengthUnit unit) {
  const std::string text = detail::read_file_bytes(path);
  LineReader reader(text, path.string());
  const double scale_to_cm = centimetres_per(unit);
  struct Vertex {
    std::uint64_t index;
    std::int64_t line;
    Pose pose_cm;
  };
  std::vector<Vertex> vertices;
  std::array<double, 7> values{};
  for_each_data_line(reader, [&](const LineTokens& tokens, std::size_t count) {
    require_value_count(reader, count, 8, "graph: vK x y z qx qy qz qw");
    std::uint64_t index = 0;
    if (!parse_vertex_name(tokens[0], index)) {
      reader.fail(detail::quoted(tokens[0]) + " is not a vertex name vK (K = 0, 1, ...)");
    }
    detail::parse_finite_values(reader, std::span(tokens).subspan(1, 7), values, "graph");
    const Eigen::Vector3d translation_cm = Eigen::Vector3d(values[0], values[1], values[2]) * scale_to_cm;
    vertices.push_back(Vertex{index, reader.line_number(),
                              detail::pose_from_quaternion(translation_cm, values[6], values[3], values[4], values[5], reader)});
  });
  require_some(vertices, reader);
  // Scans are numbered 0..n-1; a duplicate or a gap means the file does not match its scans.
  std::stable_sort(vertices.begin(), vertices.end(), [](const Vertex& a, const Vertex& b) { return a.index < b.index; });
  std::vector<Pose> poses;
  poses.reserve(vertices.size());
  for (std::size_t k = 0; k < vertices.size(); ++k) {
    if (vertices[k].index != k) {
      const bool duplicate = k > 0 && vertices[k].index == vertices[k - 1].index;
      detail::fail_at_line(path.string(), vertices[k].line,
                           duplicate ? "vertex v" + std::to_string(vertices[k].index) + " appears twice"
                                     : "no vertex v" + std::to_string(k) + " (vertices must be v0..v" +
                                           std::to_string(vertices.size() - 1) + ")",
                           InputProblem::kInconsistentSurvey);
    }
    poses.push_back(vertices[k].pose_cm);
  }
  return poses;
}

void write_graph_poses(const fs::path& path, std::span<const Pose> poses_cm, LengthUnit unit) {
  std::string out;
  for (std::size_t k = 0; k < poses_cm.size(); ++k) {
    out += 'v';
    out += std::to_string(k);
    out += ' ';
    append_row(out, translation_and_quaternion(poses_cm[k], unit));
  }
  write_file_atomically(path, out);
}

TrajectoryFormat detect_trajectory_format(const fs::path& path) {
  const std::string text = detail::read_file_bytes(path);
  LineReader reader(text, path.string());
  LineTokens tokens;
  std::string_view line;
  while (reader.next(line)) {
    const std::string_view content = detail::strip_comment(line);
    if (detail::is_blank(content)) continue;
    const std::size_t count = detail::split_tokens(content, tokens, /*commas=*/true);
    std::uint64_t index = 0;
    if (parse_vertex_name(tokens[0], index)) return TrajectoryFormat::kGraph;
    if (count == 8) return TrajectoryFormat::kTum;
    if (count == 12) return TrajectoryFormat::kKitti;
    if (count == 4 || count == 16) return TrajectoryFormat::kMatrix4x4;
    reader.fail("cannot tell the trajectory format from a line of " + std::to_string(count) +
                " values (expected vK + 7 for a graph, 8 for TUM, 12 for KITTI, 4 or 16 for 4x4 matrices)");
  }
  detail::fail_at_line(path.string(), reader.line_number(), "no poses", InputProblem::kEmpty);
}

std::vector<Pose> read_trajectory(const fs::path& path, LengthUnit unit) {
  switch (detect_trajectory_format(path)) {
    case TrajectoryFormat::kGraph:
      return read_graph_poses(path, unit);
    case TrajectoryFormat::kTum: {
      std::vector<Pose> poses;
      for (const TimedPose& timed : read_tum(path, unit)) poses.push_back(timed.pose_cm);
      return poses;
    }
    case TrajectoryFormat::kKitti:
      return read_kitti_poses(path, unit);
    case TrajectoryFormat::kMatrix4x4:
      return read_matrix_poses(path, unit);
  }
  return {};
}

}  // namespace minemap::io
