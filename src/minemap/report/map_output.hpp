#pragma once
// Writes what `minemap map` produces: per scan 3DTK-compatible `.frames` and `.pose`, the
// trajectory as TUM, the merged reduced map as PLY, report.json, the paper's Fig. 6 views
// (top.png, side.png) and map.html, a 3D view for a browser. Every file is written atomically
// (temp file + rename).
//
// Frames and units: what a person opens (map.ply, trajectory.tum, map.html, top.png, side.png) is
// in metres, right-handed, z up, whatever the survey's frame (a uos survey's 3DTK frame is turned:
// x = z_3dtk, y = -x_3dtk, z = y_3dtk). 3DTK's own files (.frames, .pose) and report.json keep the
// survey's frame and unit (report.json says which: "unit", "frame"), for 3DTK's tools and exports.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "minemap/io/formats.hpp"
#include "minemap/slam/survey_matching.hpp"

namespace minemap {

/// One option of a run as report.json's "settings" records it (the command line makes them from its
/// option definitions: every option, given or not).
struct RecordedSetting {
  enum class Kind { kFlag, kNumber, kNumbers, kText };
  std::string name;  ///< the option's name as a Python keyword: --max-pair-dist-cm is "max_pair_dist_cm"
  Kind kind = Kind::kText;
  /// kFlag: "true" or "false"; kNumber: the value's shortest round-trip text; kNumbers: such texts,
  /// comma-separated; kText: as given (empty: not given, written as null).
  std::string value;
  /// false: where and how the run ran (threads, backend, what it prints): report.json "run_options",
  /// the rest "settings".
  bool changes_poses = true;
};

struct MapOutputSettings {
  LengthUnit unit = LengthUnit::kCentimetre;  ///< the survey's unit: .frames, .pose and report.json use it
  /// The survey is in 3DTK's frame (io::Survey::frame_3dtk): the person-facing outputs turn it.
  bool survey_in_3dtk_frame = true;
  std::string survey;                         ///< the survey's path (report.json "survey")
  std::string format;                         ///< its format ("uos", "pcd", ...: report.json "format")
  std::vector<std::string> sources;           ///< each scan's file (report.json scans[i].source)
  std::string title;                          ///< drawn on the pictures
  double load_s = 0.0;                        ///< reading time, for the report
  std::string backend_choice;                 ///< how the backend was chosen (make_backend's message)
  /// The survey's scan count; more than the result holds: an interrupted run's partial map (report.json
  /// says "partial"). 0: the result's own count.
  std::size_t survey_scans = 0;
  /// The survey's local frame in its files' frame (io::Survey::origin_cm): report.json's "origin".
  Eigen::Vector3d origin_cm = Eigen::Vector3d::Zero();
  std::string version;                    ///< minemap's version (report.json "version")
  std::vector<std::string> command_line;  ///< the run's arguments, program first (report.json)
  std::vector<RecordedSetting> settings;  ///< every option (report.json "settings", "run_options"; empty: none)
  /// The pictures (top.png, side.png, map.html) draw at most this many points: every k-th point of
  /// each scan above it (map.ply always holds every point). 16 million points (about 1 400 simulated
  /// scans) are drawn whole; a longer survey's pictures would otherwise hold it all in memory.
  std::size_t picture_points_max = 16'000'000;
};

/// Pose errors before (odometry) and after registration, when the survey has reference poses.
struct TruthComparison {
  PoseErrors odometry;
  PoseErrors registered;
};

std::optional<TruthComparison> compare_with_truth(const MappingResult& result,
                                                  const std::optional<std::vector<Pose>>& truth_cm);

/// report.json's text (truth: compare_with_truth's, made once by the caller; write_s: the time
/// writing the other outputs took, for its timings).
std::string map_report(const MappingResult& result, const std::optional<TruthComparison>& truth,
                       const MappingSettings& settings, const MapOutputSettings& output, double write_s = 0.0);

/// Writes every output into `out_dir` (created if missing): truth_cm draws the reference trajectory
/// in the views, `truth` is its comparison (compare_with_truth). Returns the report as JSON text.
std::string write_map_outputs(const std::filesystem::path& out_dir, const MappingResult& result,
                              const std::optional<std::vector<Pose>>& truth_cm,
                              const std::optional<TruthComparison>& truth, const MappingSettings& settings,
                              const MapOutputSettings& output);

}  // namespace minemap
