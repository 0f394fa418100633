// A survey is a folder of scans in one of four layouts (formats.hpp, read_survey). This file tells
// the layouts apart, reads every scan and its poses, and writes the uos layout.
//
// Choices:
//  - A folder holding scans of two layouts (e.g. *.pcd and scanNNN.3d) is refused rather than
//    guessed at; so is a folder with none.
//  - uos numbering may have gaps (scan000, scan002, ...): scans are kept in number order. Two files
//    with the same number (scan001.3d and scan0001.3d) are an error.
//  - uos: every scanNNN.3d needs scanNNN.pose unless `initial_poses` is given (then the .pose files
//    are not read). truth/ is optional, but if it holds any scanNNN.pose it must hold all of them.
//  - pcd: a scan's initial pose is its file's VIEWPOINT (read_pcd; the identity in practice) unless
//    `initial_poses` is given; ply and kitti start from the identity.
//  - One unit for the whole folder: ReadSettings::unit, else the format's default, applies to the
//    points, the .pose files, truth and `initial_poses` alike; so does right_handed_to_3dtk.
//  - Scans are read one after another, so the first bad file in name order is the one reported.
#include <algorithm>
#include <cstdio>
#include <map>
#include <string>
#include <system_error>
#include <vector>

#include "minemap/core/error.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/io/text_reader.hpp"

namespace minemap::io {
namespace {

bool all_digits(std::string_view text) {
  return !text.empty() && std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; });
}

/// The number of a 3DTK scan file name "scanNNN.3d" (at least 3 digits), if it is one.
std::optional<std::uint64_t> uos_scan_number(const std::string& file_name) {
  constexpr std::string_view kPrefix = "scan";
  constexpr std::string_view kSuffix = ".3d";
  if (file_name.size() < kPrefix.size() + 3 + kSuffix.size() || !file_name.starts_with(kPrefix) ||
      !file_name.ends_with(kSuffix)) {
    return std::nullopt;
  }
  const std::string_view digits =
      std::string_view(file_name).substr(kPrefix.size(), file_name.size() - kPrefix.size() - kSuffix.size());
  std::uint64_t number = 0;
  if (!all_digits(digits) || !detail::parse_uint64(digits, number)) return std::nullopt;
  return number;
}

std::string uos_stem(std::size_t index) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "scan%03zu", index);
  return buffer;
}

/// What a folder holds, by layout.
struct FolderContent {
  std::map<std::uint64_t, fs::path> uos;  ///< by scan number
  std::vector<fs::path> pcd;
  std::vector<fs::path> ply;
  std::vector<fs::path> kitti_bin;       ///< NNNNNN.bin: x y z intensity
  std::vector<fs::path> kitti_xyz_dirs;  ///< NNNNNN/points.bin: x y z
};

FolderContent list_folder(const fs::path& dir) {
  std::error_code error;
  if (!fs::is_directory(dir, error)) detail::fail_in_file(dir.string(), "is not a folder");
  FolderContent content;
  for (const auto& entry : fs::directory_iterator(dir, error)) {
    const fs::path& path = entry.path();
    const std::string file_name = path.filename().string();
    std::error_code entry_error;
    if (entry.is_directory(entry_error)) {
      if (all_digits(file_name) && fs::is_regular_file(path / "points.bin", entry_error)) {
        content.kitti_xyz_dirs.push_back(path);
      }
      continue;
    }
    if (const auto number = uos_scan_number(file_name)) {
      const auto [existing, inserted] = content.uos.emplace(*number, path);
      if (!inserted) {
        detail::fail_in_file(path.string(), "has the same scan number as " + existing->second.filename().string());
      }
    } else if (path.extension() == ".pcd") {
      content.pcd.push_back(path);
    } else if (path.extension() == ".ply") {
      content.ply.push_back(path);
    } else if (path.extension() == ".bin" && all_digits(path.stem().string())) {
      content.kitti_bin.push_back(path);
    }
  }
  if (error) detail::fail_in_file(dir.string(), "cannot list the folder: " + error.message());
  for (auto* list : {&content.pcd, &content.ply, &content.kitti_bin, &content.kitti_xyz_dirs}) {
    std::sort(list->begin(), list->end());
  }
  return content;
}

Pose in_3dtk_frame(const Pose& pose_cm, const ReadSettings& settings) {
  return settings.right_handed_to_3dtk ? right_handed_pose_to_3dtk(pose_cm, 1.0) : pose_cm;
}

std::vector<Pose> read_pose_list(const fs::path& path, LengthUnit unit, std::size_t expected_count,
                                 const ReadSettings& settings) {
  std::vector<Pose> poses = read_trajectory(path, unit);
  if (poses.size() != expected_count) {
    detail::fail_in_file(path.string(), "has " + std::to_string(poses.size()) + " poses, the survey has " +
                                            std::to_string(expected_count) + " scans");
  }
  for (Pose& pose : poses) pose = in_3dtk_frame(pose, settings);
  return poses;
}

Pose read_pose_file(const fs::path& path, LengthUnit unit, const ReadSettings& settings) {
  return in_3dtk_frame(euler_to_pose(read_uos_pose(path, unit)), settings);
}

void read_uos_layout(const fs::path& dir, const FolderContent& content, const SurveyReadSettings& settings, Survey& survey) {
  const bool need_pose_files = !settings.initial_poses.has_value();
  std::size_t truth_files = 0;
  for (const auto& [number, path] : content.uos) {
    Scan scan = read_uos_points(path, settings.read);
    if (need_pose_files) {
      const fs::path pose_path = fs::path(path).replace_extension(".pose");
      if (!fs::exists(pose_path)) {
        detail::fail_in_file(pose_path.string(), "missing: " + path.filename().string() +
                                                     " needs its pose file (or give initial poses)");
      }
      scan.pose_cm = read_pose_file(pose_path, survey.unit, settings.read);
    }
    truth_files += fs::exists(dir / "truth" / (scan.name + ".pose")) ? 1 : 0;
    survey.scans.push_back(std::move(scan));
  }
  if (truth_files == 0) return;
  std::vector<Pose> truth;
  for (const Scan& scan : survey.scans) {
    const fs::path truth_path = dir / "truth" / (scan.name + ".pose");
    if (!fs::exists(truth_path)) {
      detail::fail_in_file(truth_path.string(), "missing: truth/ has poses for some scans, so it needs all of them");
    }
    truth.push_back(read_pose_file(truth_path, survey.unit, settings.read));
  }
  survey.truth_cm = std::move(truth);
}

}  // namespace

Survey read_survey(const fs::path& dir, const SurveyReadSettings& settings) {
  const FolderContent content = list_folder(dir);
  const int layouts = !content.uos.empty() + !content.pcd.empty() + !content.ply.empty() +
                      !content.kitti_bin.empty() + !content.kitti_xyz_dirs.empty();
  if (layouts == 0) {
    detail::fail_in_file(dir.string(), "no scans found (expected scanNNN.3d, *.pcd, *.ply, NNNNNN.bin or NNNNNN/points.bin)");
  }
  if (layouts > 1) {
    detail::fail_in_file(dir.string(), "holds scans of several layouts (" + std::to_string(content.uos.size()) + " .3d, " +
                                           std::to_string(content.pcd.size()) + " .pcd, " +
                                           std::to_string(content.ply.size()) + " .ply, " +
                                           std::to_string(content.kitti_bin.size() + content.kitti_xyz_dirs.size()) +
                                           " KITTI .bin); put each survey in its own folder");
  }
  Survey survey;
  const ReadSettings& read = settings.read;
  if (!content.uos.empty()) {
    survey.format = "uos";
    survey.unit = read.unit.value_or(LengthUnit::kCentimetre);
    read_uos_layout(dir, content, settings, survey);
  } else if (!content.pcd.empty()) {
    survey.format = "pcd";
    survey.unit = read.unit.value_or(LengthUnit::kMetre);
    for (const fs::path& path : content.pcd) survey.scans.push_back(read_pcd(path, read));  // pose = VIEWPOINT
  } else if (!content.ply.empty()) {
    survey.format = "ply";
    survey.unit = read.unit.value_or(LengthUnit::kMetre);
    for (const fs::path& path : content.ply) survey.scans.push_back(read_ply(path, read));
  } else {
    survey.format = "kitti";
    survey.unit = read.unit.value_or(LengthUnit::kMetre);
    for (const fs::path& path : content.kitti_bin) survey.scans.push_back(read_kitti_bin(path, read, 4));
    for (const fs::path& folder : content.kitti_xyz_dirs) {
      Scan scan = read_kitti_bin(folder / "points.bin", read, 3);
      scan.name = folder.filename().string();  // "000002", not "points"
      survey.scans.push_back(std::move(scan));
    }
    const fs::path graph = dir / "graph.txt";
    if (fs::exists(graph)) survey.truth_cm = read_pose_list(graph, survey.unit, survey.scans.size(), read);
  }
  if (settings.initial_poses) {
    const std::vector<Pose> poses = read_pose_list(*settings.initial_poses, survey.unit, survey.scans.size(), read);
    for (std::size_t i = 0; i < poses.size(); ++i) survey.scans[i].pose_cm = poses[i];
  }
  return survey;
}

void write_uos_survey(const fs::path& dir, std::span<const Scan> scans, const std::optional<std::vector<Pose>>& truth_cm) {
  if (truth_cm && truth_cm->size() != scans.size()) {
    throw std::invalid_argument("write_uos_survey: " + std::to_string(truth_cm->size()) + " truth poses for " +
                                std::to_string(scans.size()) + " scans");
  }
  std::error_code error;
  fs::create_directories(dir, error);
  if (error) throw OutputError("cannot create " + dir.string() + ": " + error.message());
  // Scans are renumbered 0..n-1. A higher-numbered scan left from an earlier survey would silently
  // join this one when the folder is read back, so it is refused.
  for (const auto& entry : fs::directory_iterator(dir, error)) {
    const auto number = uos_scan_number(entry.path().filename().string());
    if (number && *number >= scans.size()) {
      throw OutputError("cannot write a survey of " + std::to_string(scans.size()) + " scans into " + dir.string() +
                        ": it already holds " + entry.path().filename().string() + " (use an empty folder)");
    }
  }
  // Likewise a truth/ folder left from an earlier survey would be read back as this one's truth.
  if (!truth_cm) {
    for (const auto& entry : fs::directory_iterator(dir / "truth", error)) {
      if (entry.path().extension() == ".pose") {
        throw OutputError("cannot write a survey without truth into " + dir.string() + ": it already holds " +
                          (fs::path("truth") / entry.path().filename()).string() + " (use an empty folder)");
      }
    }
  }
  for (std::size_t i = 0; i < scans.size(); ++i) {
    const std::string stem = uos_stem(i);
    write_uos_points(dir / (stem + ".3d"), scans[i]);
    write_uos_pose(dir / (stem + ".pose"), scans[i].pose_cm);
  }
  if (truth_cm) {
    fs::create_directories(dir / "truth", error);
    if (error) throw OutputError("cannot create " + (dir / "truth").string() + ": " + error.message());
    for (std::size_t i = 0; i < scans.size(); ++i) write_uos_pose(dir / "truth" / (uos_stem(i) + ".pose"), (*truth_cm)[i]);
  }
}

}  // namespace minemap::io
