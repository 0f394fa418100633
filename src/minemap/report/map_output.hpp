#pragma once
// Writes what `minemap map` produces: per scan 3DTK-compatible `.frames` and `.pose`, the
// trajectory as TUM, the merged reduced map as PLY, report.json, the paper's Fig. 6 views
// (top.png, side.png) and map.html, a 3D view for a browser. Every file is written atomically
// (temp file + rename).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "minemap/io/formats.hpp"
#include "minemap/slam/survey_matching.hpp"

namespace minemap {

struct MapOutputSettings {
  LengthUnit unit = LengthUnit::kCentimetre;  ///< the survey's unit: poses and map are written in it
  int up_axis = 1;                            ///< 1 (y) for 3DTK frames, 2 (z) for right-handed ones
  std::string title;                          ///< drawn on the pictures
  double load_s = 0.0;                        ///< reading time, for the report
  std::string backend_choice;                 ///< how the backend was chosen (make_backend's message)
  /// The survey's scan count; more than the result holds: an interrupted run's partial map (report.json
  /// says "partial"). 0: the result's own count.
  std::size_t survey_scans = 0;
  /// The survey's local frame in its files' frame (io::Survey::origin_cm): report.json's "origin".
  Eigen::Vector3d origin_cm = Eigen::Vector3d::Zero();
};

/// Pose errors before (odometry) and after registration, when the survey has reference poses.
struct TruthComparison {
  PoseErrors odometry;
  PoseErrors registered;
};

std::optional<TruthComparison> compare_with_truth(const MappingResult& result,
                                                  const std::optional<std::vector<Pose>>& truth_cm);

/// report.json's text (write_s: the time writing the other outputs took, for its timings).
std::string map_report(const MappingResult& result, const std::optional<std::vector<Pose>>& truth_cm,
                       const MappingSettings& settings, const MapOutputSettings& output, double write_s = 0.0);

/// Writes every output into `out_dir` (created if missing). Returns the report as JSON text.
std::string write_map_outputs(const std::filesystem::path& out_dir, const MappingResult& result,
                              const std::optional<std::vector<Pose>>& truth_cm, const MappingSettings& settings,
                              const MapOutputSettings& output);

}  // namespace minemap
