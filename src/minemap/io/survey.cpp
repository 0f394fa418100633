// A survey is a folder of scans in one of four layouts (formats.hpp, read_survey). This file tells
// the layouts apart, reads every scan and its poses, and writes the uos layout.
//
// Choices:
//  - A folder holding scans of two layouts (e.g. *.pcd and scanNNN.3d) is refused rather than
//    guessed at; so is a folder with none.
//  - uos (and KITTI) numbering may have gaps (scan000, scan002, ...): scans are kept in number order
//    and the gap is a Survey::warnings line naming the missing numbers. A .pose file holds absolute
//    odometry, so nothing is lost but the overlap of the missing scan (3DTK's -s/-e range would stop
//    reading at the gap instead). Two files with the same number (scan001.3d and scan0001.3d), or two
//    scans with exactly the same points (a copied file), are an error naming both files.
//  - uos: every scanNNN.3d needs scanNNN.pose unless `initial_poses` is given (then the .pose files
//    are not read). truth/ is optional, but if it holds any scanNNN.pose it must hold all of them.
//  - pcd: a scan's initial pose is its file's VIEWPOINT (read_pcd; the identity in practice) unless
//    `initial_poses` is given; ply and kitti start from the identity.
//  - One unit for the whole folder: ReadSettings::unit, else the format's default, applies to the
//    points, the .pose files, truth and `initial_poses` alike; so does right_handed_to_3dtk.
//  - Scans are read one after another, so the first bad file in name order is the one reported; the
//    checks of the survey as a whole (too few points, duplicates, units) come after every file parsed.
//  - Units: with the unit left to uos' default (cm), a survey whose every scan (of >= 100 points)
//    spans less than 1 m is refused (kSuspiciousUnits): that is a survey in metres read as cm, which
//    the cm thresholds (25 cm pairs, 10 cm reduction) would silently fail to register. An explicit
//    unit (--unit cm) is trusted. The other direction (cm read as m) is not guessed at: surveys in
//    metres spanning kilometres are real.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstring>
#include <exception>
#include <limits>
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
  std::vector<fs::path> xyz;             ///< .xyz, .asc, and .txt files that hold points
  std::vector<fs::path> kitti_bin;       ///< NNNNNN.bin: x y z intensity
  std::vector<fs::path> kitti_xyz_dirs;  ///< NNNNNN/points.bin: x y z
};

/// File names in natural order: runs of digits compare as numbers (full2 before full10), everything
/// else byte by byte; names equal that way (full01, full1) fall back to byte order.
bool natural_less(const std::string& a, const std::string& b) {
  const auto digit = [](char c) { return c >= '0' && c <= '9'; };
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (digit(a[i]) && digit(b[j])) {
      std::size_t i_end = i, j_end = j;
      while (i_end < a.size() && digit(a[i_end])) ++i_end;
      while (j_end < b.size() && digit(b[j_end])) ++j_end;
      std::size_t i_start = i, j_start = j;  // leading zeros do not count
      while (i_start + 1 < i_end && a[i_start] == '0') ++i_start;
      while (j_start + 1 < j_end && b[j_start] == '0') ++j_start;
      const std::string_view x(a.data() + i_start, i_end - i_start), y(b.data() + j_start, j_end - j_start);
      if (x.size() != y.size()) return x.size() < y.size();
      if (x != y) return x < y;
      i = i_end;
      j = j_end;
      continue;
    }
    if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
    ++i;
    ++j;
  }
  if ((i < a.size()) != (j < b.size())) return j < b.size();
  return a < b;
}

FolderContent list_folder(const fs::path& dir) {
  std::error_code error;
  if (fs::is_regular_file(dir, error)) {
    detail::fail_in_file(dir.string(),
                         "is a file, not a folder: minemap maps a folder of scans, one file each; to map this scan "
                         "alone, put it in a folder of its own (mkdir one && cp " + dir.filename().string() +
                             " one/)");
  }
  if (!fs::is_directory(dir, error)) detail::fail_in_file(dir.string(), "is not a folder");
  FolderContent content;
  std::vector<fs::path> text_files;  // .txt: points only in a folder of nothing else (README.txt is not)
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
        detail::fail_in_file(path.string(), "has the same scan number as " + existing->second.filename().string(),
                             InputProblem::kInconsistentSurvey);
      }
    } else if (path.extension() == ".pcd") {
      content.pcd.push_back(path);
    } else if (path.extension() == ".ply") {
      content.ply.push_back(path);
    } else if (path.extension() == ".xyz" || path.extension() == ".asc") {
      content.xyz.push_back(path);
    } else if (path.extension() == ".txt") {
      text_files.push_back(path);
    } else if (path.extension() == ".bin" && all_digits(path.stem().string())) {
      content.kitti_bin.push_back(path);
    }
  }
  if (error) detail::fail_in_file(dir.string(), "cannot list the folder: " + error.message());
  if (content.uos.empty() && content.pcd.empty() && content.ply.empty() && content.kitti_bin.empty() &&
      content.kitti_xyz_dirs.empty()) {
    for (const fs::path& path : text_files) {
      if (looks_like_xyz_text(path)) content.xyz.push_back(path);
    }
  }
  for (auto* list : {&content.pcd, &content.ply, &content.xyz, &content.kitti_bin, &content.kitti_xyz_dirs}) {
    std::sort(list->begin(), list->end(), [](const fs::path& a, const fs::path& b) {
      return natural_less(a.filename().string(), b.filename().string());
    });
  }
  return content;
}

Pose in_3dtk_frame(const Pose& pose_cm, const ReadSettings& settings) {
  return settings.right_handed_to_3dtk ? right_handed_pose_to_3dtk(pose_cm, 1.0) : pose_cm;
}

/// Whether a pose file is one 4x4 matrix (4 lines of 4 values, or one of 16): a registration's
/// relative transform, not a trajectory that lacks a pose (a TUM, KITTI or graph file of one).
bool is_one_matrix(const fs::path& path) {
  const std::string text = detail::read_file_bytes(path);
  detail::LineReader reader(text, path.string());
  std::vector<std::size_t> counts;
  std::array<std::string_view, 17> tokens;
  std::string_view line;
  while (reader.next(line)) {
    const std::string_view content = detail::strip_comment(line);
    if (detail::is_blank(content)) continue;
    counts.push_back(detail::split_tokens(content, tokens, /*commas=*/true));
  }
  return counts == std::vector<std::size_t>{4, 4, 4, 4} || counts == std::vector<std::size_t>{16};
}

/// One pose per scan of the survey (a two-scan survey: also one 4x4 matrix, the second scan's relative to the
/// first); with a scan range (SurveyReadSettings::first_scan, max_scans),
/// the file covers the folder's scans up to the range's end, and the range's poses are returned.
std::vector<Pose> read_pose_list(const fs::path& path, LengthUnit unit, std::size_t expected_count,
                                 const ReadSettings& settings, std::size_t first_scan = 0, bool ranged = false) {
  std::vector<Pose> poses = read_trajectory(path, unit);
  if (ranged && poses.size() >= first_scan + expected_count) {
    poses = std::vector<Pose>(poses.begin() + static_cast<std::ptrdiff_t>(first_scan),
                              poses.begin() + static_cast<std::ptrdiff_t>(first_scan + expected_count));
  } else if (ranged) {
    detail::fail_in_file(path.string(),
                         "has " + std::to_string(poses.size()) + " poses, the survey's scans so far need " +
                             std::to_string(first_scan + expected_count),
                         InputProblem::kInconsistentSurvey);
  }
  // A pair's one relative transform (fast_gicp's, Open3D's and PCL's registration results:
  // T_first_second, mapping the second scan into the first's frame) is the pose list
  // {identity, T}: the first scan is the frame.
  if (!ranged && expected_count == 2 && poses.size() == 1 && is_one_matrix(path)) {
    poses.insert(poses.begin(), Pose::Identity());
  }
  if (poses.size() != expected_count) {
    detail::fail_in_file(path.string(),
                         "has " + std::to_string(poses.size()) + " poses, the survey has " +
                             std::to_string(expected_count) + " scans",
                         InputProblem::kInconsistentSurvey);
  }
  for (Pose& pose : poses) pose = in_3dtk_frame(pose, settings);
  return poses;
}

Pose read_pose_file(const fs::path& path, LengthUnit unit, const ReadSettings& settings) {
  return in_3dtk_frame(euler_to_pose(read_uos_pose(path, unit)), settings);
}

/// NaN points dropped per file, for one warning line.
struct DroppedPoints {
  std::vector<std::pair<std::string, std::uint64_t>> files;  ///< file name, NaN points dropped
  std::uint64_t total = 0;
};

/// Reads every file with `read` at once (TBB over files: parsing text is most of the reading time),
/// and returns the scans in the order of `paths`. A file that fails is reported as a sequential
/// read would report it: the first failing file in order throws, after its predecessors' results
/// were checked by the caller in order (`at` rethrows file k's error when the caller reaches k).
class ParallelReads {
 public:
  template <class Read>
  ParallelReads(const std::vector<fs::path>& paths, const ReadSettings& settings, Read&& read)
      : scans_(paths.size()), reports_(paths.size()), errors_(paths.size()), paths_(paths) {
    tbb::parallel_for(std::size_t{0}, paths.size(), [&](std::size_t k) {
      try {
        ReadSettings counted = settings;
        counted.report = &reports_[k];
        scans_[k] = read(paths[k], counted);
      } catch (...) {
        errors_[k] = std::current_exception();
      }
    });
  }
  /// Scan k (moved out), counting its NaN points into `dropped`; rethrows its read error.
  Scan take(std::size_t k, DroppedPoints& dropped) {
    if (errors_[k]) std::rethrow_exception(errors_[k]);
    if (reports_[k].nan_points_dropped > 0) {
      dropped.files.emplace_back(paths_[k].filename().string(), reports_[k].nan_points_dropped);
      dropped.total += reports_[k].nan_points_dropped;
    }
    return std::move(scans_[k]);
  }
  std::uint64_t slices_detected(std::size_t k) const { return reports_[k].slices_detected; }

 private:
  std::vector<Scan> scans_;
  std::vector<ReadReport> reports_;
  std::vector<std::exception_ptr> errors_;
  const std::vector<fs::path>& paths_;
};

void read_uos_layout(const fs::path& dir, const FolderContent& content, const SurveyReadSettings& settings, Survey& survey,
                     DroppedPoints& dropped) {
  const bool need_pose_files = !settings.initial_poses.has_value();
  std::size_t truth_files = 0;
  std::vector<fs::path> paths;
  for (const auto& entry : content.uos) paths.push_back(entry.second);
  ParallelReads reads(paths, settings.read, [](const fs::path& p, const ReadSettings& s) { return read_uos_points(p, s); });
  std::size_t detected = 0;
  for (std::size_t k = 0; k < paths.size(); ++k) {
    const fs::path& path = paths[k];
    Scan scan = reads.take(k, dropped);
    detected += reads.slices_detected(k) > 0 ? 1 : 0;
    if (need_pose_files) {
      const fs::path pose_path = fs::path(path).replace_extension(".pose");
      if (!fs::exists(pose_path)) {
        detail::fail_in_file(pose_path.string(),
                             "missing: " + path.filename().string() + " needs its pose file (or give initial poses)",
                             InputProblem::kInconsistentSurvey);
      }
      scan.pose_cm = read_pose_file(pose_path, survey.unit, settings.read);
    }
    truth_files += fs::exists(dir / "truth" / (scan.name + ".pose")) ? 1 : 0;
    survey.scans.push_back(std::move(scan));
  }
  if (detected > 0) {
    // Not a problem; said because it changes what the slice filter does with these files.
    survey.warnings.push_back(std::to_string(detected) + " of " + std::to_string(paths.size()) +
                              " uos files have no '# slice' markers: their slices were found from the scanner "
                              "order of the points (--points-per-slice N sets them, --no-slice-detection leaves "
                              "them without)");
  }
  if (truth_files == 0) return;
  std::vector<Pose> truth;
  for (const Scan& scan : survey.scans) {
    const fs::path truth_path = dir / "truth" / (scan.name + ".pose");
    if (!fs::exists(truth_path)) {
      detail::fail_in_file(truth_path.string(), "missing: truth/ has poses for some scans, so it needs all of them",
                           InputProblem::kInconsistentSurvey);
    }
    truth.push_back(read_pose_file(truth_path, survey.unit, settings.read));
  }
  survey.truth_cm = std::move(truth);
}

/// "scan001, scan004..scan006" for the numbers missing between the first and the last of `numbers`
/// (sorted), named by `name_of`; empty when there is no gap.
template <class NameOf>
std::string describe_gaps(const std::vector<std::uint64_t>& numbers, NameOf&& name_of) {
  constexpr int kMaxRangesShown = 8;
  std::string text;
  int ranges = 0;
  for (std::size_t k = 1; k < numbers.size(); ++k) {
    if (numbers[k] <= numbers[k - 1] + 1) continue;
    const std::uint64_t first = numbers[k - 1] + 1, last = numbers[k] - 1;
    if (++ranges > kMaxRangesShown) {
      text += ", ...";
      break;
    }
    if (!text.empty()) text += ", ";
    text += name_of(first);
    if (last > first) text += ".." + name_of(last);
  }
  return text;
}

std::string kitti_stem(std::uint64_t number) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%06llu", static_cast<unsigned long long>(number));
  return buffer;
}

/// The number of a KITTI file or folder name ("000007.bin", "000007"); all digits by construction.
std::uint64_t kitti_number(const fs::path& path) {
  std::uint64_t number = 0;
  detail::parse_uint64(path.stem().string(), number);
  return number;
}

std::string file_of(const Scan& scan) { return scan.source_path.empty() ? scan.name : scan.source_path; }

/// Every scan needs kMinScanPoints points: fewer can never be registered.
void check_scan_sizes(const std::vector<Scan>& scans) {
  for (const Scan& scan : scans) {
    if (scan.size() >= kMinScanPoints) continue;
    detail::fail_in_file(file_of(scan),
                         "holds only " + std::to_string(scan.size()) + (scan.size() == 1 ? " point" : " points") +
                             "; a scan needs at least " + std::to_string(kMinScanPoints) + " to be registered",
                         InputProblem::kEmpty);
  }
}

/// Two scans with exactly the same points are one file copied twice (a real scanner never repeats
/// its noise); matching a scan against its copy would only hide the mistake.
void check_duplicate_scans(const std::vector<Scan>& scans) {
  // One hash per scan, in parallel (hashing is a pass over every point of the survey): FNV-1a over
  // the points' 32-bit words and the local origin. Equal scans hash alike; equal hashes are compared.
  std::vector<std::uint64_t> hashes(scans.size());
  tbb::parallel_for(std::size_t{0}, scans.size(), [&](std::size_t i) {
    std::uint64_t hash = 1469598103934665603ull;
    const auto mix = [&hash](const void* data, std::size_t bytes) {
      const auto* p = static_cast<const unsigned char*>(data);
      for (std::size_t b = 0; b + 4 <= bytes; b += 4) {
        std::uint32_t word;
        std::memcpy(&word, p + b, 4);
        hash = (hash ^ word) * 1099511628211ull;
      }
    };
    mix(scans[i].points_cm.data(), scans[i].points_cm.size() * sizeof(Eigen::Vector3f));
    mix(scans[i].local_origin_cm.data(), 3 * sizeof(double));
    hashes[i] = hash;
  });
  std::map<std::uint64_t, std::size_t> by_hash;
  for (std::size_t i = 0; i < scans.size(); ++i) {
    const Scan& scan = scans[i];
    const auto [it, inserted] = by_hash.emplace(hashes[i], i);
    if (inserted) continue;
    const Scan& first = scans[it->second];
    if (first.points_cm == scan.points_cm && first.local_origin_cm == scan.local_origin_cm) {
      detail::fail_in_file(file_of(scan),
                           "holds exactly the same " + std::to_string(scan.size()) + " points as " +
                               fs::path(file_of(first)).filename().string() +
                               " (a copied file?): remove one of them",
                           InputProblem::kInconsistentSurvey);
    }
  }
}

/// Each scan's bounding-box diagonal (cm), in parallel.
std::vector<double> scan_diagonals_cm(const std::vector<Scan>& scans) {
  std::vector<double> diagonals_cm(scans.size(), 0.0);
  tbb::parallel_for(std::size_t{0}, scans.size(), [&](std::size_t i) {
    const Scan& scan = scans[i];
    if (scan.points_cm.empty()) return;
    Eigen::Vector3f lo = scan.points_cm.front(), hi = scan.points_cm.front();
    for (const Eigen::Vector3f& p : scan.points_cm) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    diagonals_cm[i] = (hi - lo).cast<double>().norm();
  });
  return diagonals_cm;
}

/// A scan whose points all coincide has no shape to match (a sensor that returned one range, a
/// writer that repeated a point): named here rather than left to fail as "no overlap".
void check_degenerate_scans(const std::vector<Scan>& scans, const std::vector<double>& diagonals_cm) {
  for (std::size_t i = 0; i < scans.size(); ++i) {
    if (diagonals_cm[i] > 0.0) continue;
    detail::fail_in_file(file_of(scans[i]),
                         "all " + std::to_string(scans[i].size()) +
                             " points are identical: no shape to register (remove the scan, or check its writer)",
                         InputProblem::kEmpty);
  }
}

/// The units check (formats.hpp, kSuspiciousScanDiagonal_cm): only for the uos default unit. The
/// median scan is judged, not the largest: one scan seeing 80 m down a drive, read as cm, still
/// spans 80 "cm", and one stray far point must not make a metres survey pass.
void check_units(const std::vector<Scan>& scans, const std::vector<double>& diagonals_cm) {
  std::vector<std::size_t> judged;
  for (std::size_t i = 0; i < scans.size(); ++i) {
    if (scans[i].size() >= kUnitCheckMinPoints) judged.push_back(i);
  }
  if (judged.empty()) return;
  std::sort(judged.begin(), judged.end(), [&](std::size_t a, std::size_t b) {
    return diagonals_cm[a] < diagonals_cm[b] || (diagonals_cm[a] == diagonals_cm[b] && a < b);
  });
  const std::size_t median = judged[(judged.size() - 1) / 2];
  if (diagonals_cm[median] >= kSuspiciousScanDiagonal_cm) return;
  char extent[96];
  std::snprintf(extent, sizeof extent, "%.3g cm (the largest of the %zu scans: %.3g cm)", diagonals_cm[median],
                judged.size(), diagonals_cm[judged.back()]);
  detail::fail_in_file(file_of(scans[median]),
                       std::string("the median scan spans only ") + extent +
                           ", read in cm, uos' default unit: a survey's scans span metres. Is it in metres? Map it "
                           "with --unit m (or --unit cm if it really is this small)",
                       InputProblem::kSuspiciousUnits);
}

std::string describe_dropped(const DroppedPoints& dropped) {
  constexpr std::size_t kMaxFilesShown = 5;
  std::string text = "dropped " + std::to_string(dropped.total) + " point" + (dropped.total == 1 ? "" : "s") +
                     " with a NaN coordinate (no-return markers) in " + std::to_string(dropped.files.size()) +
                     (dropped.files.size() == 1 ? " file: " : " files: ");
  for (std::size_t k = 0; k < dropped.files.size() && k < kMaxFilesShown; ++k) {
    if (k > 0) text += ", ";
    text += dropped.files[k].first + " (" + std::to_string(dropped.files[k].second) + ")";
  }
  if (dropped.files.size() > kMaxFilesShown) text += ", ...";
  return text;
}

}  // namespace

namespace {
/// The layouts read here: uos, PCD, PLY, KITTI.
bool ranged(const SurveyReadSettings& settings) {
  return settings.first_scan > 0 || settings.max_scans != std::numeric_limits<std::size_t>::max();
}

/// Keeps the scans of SurveyReadSettings' range (natural order), each layout's list alike.
void keep_range(FolderContent& content, const SurveyReadSettings& settings) {
  if (!ranged(settings)) return;
  const auto in_range = [&](std::size_t k) { return k >= settings.first_scan && k - settings.first_scan < settings.max_scans; };
  std::map<std::uint64_t, fs::path> uos;
  std::size_t k = 0;
  for (auto& entry : content.uos) {
    if (in_range(k++)) uos.insert(entry);
  }
  content.uos = std::move(uos);
  for (auto* list : {&content.pcd, &content.ply, &content.xyz, &content.kitti_bin, &content.kitti_xyz_dirs}) {
    std::vector<fs::path> kept;
    for (std::size_t j = 0; j < list->size(); ++j) {
      if (in_range(j)) kept.push_back((*list)[j]);
    }
    *list = std::move(kept);
  }
}

/// Moves a survey in world coordinates near zero (Survey::origin_cm): its origin is `given`, or the
/// first scan's position rounded to kLocalOriginGrid_cm (100 m) when that lies beyond
/// kWorldCoordinates_cm. The files'
/// frame and the world both move by -origin: each scan's points keep their float values (their
/// local origin moves), and each pose T_world_file becomes T(-o) T_world_file T(o), the identity
/// staying the identity, so poses, views and .pose files stay near zero.
void choose_local_origin(Survey& survey, const std::optional<Eigen::Vector3d>& given) {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  if (given) {
    origin = *given;
  } else if (!survey.scans.empty()) {
    const Eigen::Vector3d first = survey.scans.front().world_from_points().block<3, 1>(0, 3);
    if (first.norm() > kWorldCoordinates_cm) origin = (first / kLocalOriginGrid_cm).array().round().matrix() * kLocalOriginGrid_cm;
  }
  survey.origin_cm = origin;
  if (origin.isZero()) return;
  const auto moved = [&](Pose pose) {  // T(-o) * pose * T(o)
    pose.block<3, 1>(0, 3) += pose.block<3, 3>(0, 0) * origin - origin;
    return pose;
  };
  for (Scan& scan : survey.scans) {
    scan.local_origin_cm -= origin;
    scan.pose_cm = moved(scan.pose_cm);
  }
  if (survey.truth_cm) {
    for (Pose& pose : *survey.truth_cm) pose = moved(pose);
  }
}

void read_native_survey(const fs::path& dir, const SurveyReadSettings& settings, Survey& survey, DroppedPoints& dropped,
                        std::vector<std::uint64_t>& numbers, std::string (*&name_of)(std::uint64_t)) {
  FolderContent content = list_folder(dir);
  keep_range(content, settings);
  const int layouts = !content.uos.empty() + !content.pcd.empty() + !content.ply.empty() + !content.xyz.empty() +
                      !content.kitti_bin.empty() + !content.kitti_xyz_dirs.empty();
  if (layouts == 0) {
    detail::fail_in_file(dir.string(),
                         "no scans found (expected scanNNN.3d, *.pcd, *.ply, *.xyz / *.asc / *.txt (ASCII x y z), "
                         "NNNNNN.bin or NNNNNN/points.bin)",
                         InputProblem::kEmpty);
  }
  if (layouts > 1) {
    detail::fail_in_file(dir.string(),
                         "holds scans of several layouts (" + std::to_string(content.uos.size()) + " .3d, " +
                             std::to_string(content.pcd.size()) + " .pcd, " + std::to_string(content.ply.size()) +
                             " .ply, " + std::to_string(content.xyz.size()) + " .xyz, " + std::to_string(content.kitti_bin.size() + content.kitti_xyz_dirs.size()) +
                             " KITTI .bin); put each survey in its own folder",
                         InputProblem::kInconsistentSurvey);
  }
  const ReadSettings& read = settings.read;
  if (!content.uos.empty()) {
    survey.format = "uos";
    survey.unit = read.unit.value_or(LengthUnit::kCentimetre);
    read_uos_layout(dir, content, settings, survey, dropped);
    for (const auto& entry : content.uos) numbers.push_back(entry.first);
    name_of = [](std::uint64_t number) { return uos_stem(static_cast<std::size_t>(number)); };
  } else if (!content.pcd.empty() || !content.ply.empty() || !content.xyz.empty()) {
    // Every file at once, as uos' (each scan read alone: the same scans as one after another).
    const std::vector<fs::path>& paths = !content.pcd.empty() ? content.pcd
                                         : !content.ply.empty() ? content.ply
                                                                : content.xyz;
    survey.format = !content.pcd.empty() ? "pcd" : !content.ply.empty() ? "ply" : "xyz";
    survey.unit = read.unit.value_or(LengthUnit::kMetre);
    ParallelReads reads(paths, read, [&](const fs::path& p, const ReadSettings& s) {
      return read_scan_file(p, survey.format, s);  // a PCD's pose: its VIEWPOINT
    });
    for (std::size_t k = 0; k < paths.size(); ++k) survey.scans.push_back(reads.take(k, dropped));
  } else {
    survey.format = "kitti";
    survey.unit = read.unit.value_or(LengthUnit::kMetre);
    std::vector<fs::path> paths = content.kitti_bin;
    for (const fs::path& folder : content.kitti_xyz_dirs) paths.push_back(folder / "points.bin");
    ParallelReads reads(paths, read, [](const fs::path& p, const ReadSettings& s) { return read_scan_file(p, "kitti", s); });
    for (std::size_t k = 0; k < paths.size(); ++k) {
      survey.scans.push_back(reads.take(k, dropped));
      // NNNNNN.bin or NNNNNN/points.bin (read_scan_file names the latter by its folder)
      numbers.push_back(kitti_number(k < content.kitti_bin.size() ? paths[k] : paths[k].parent_path()));
    }
    // Both KITTI layouts in one folder would interleave; numbers are only meaningful for one.
    if (!content.kitti_bin.empty() && !content.kitti_xyz_dirs.empty()) numbers.clear();
    const fs::path graph = dir / "graph.txt";
    if (fs::exists(graph)) {
      survey.truth_cm = read_pose_list(graph, survey.unit, survey.scans.size(), read, settings.first_scan, ranged(settings));
    }
  }
}
}  // namespace

namespace {
ForeignSurveyReader& foreign_reader() {
  static ForeignSurveyReader reader;
  return reader;
}
bool is_foreign_file(const fs::path& path) {
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return extension == ".las" || extension == ".laz" || extension == ".e57";
}

/// A LAS/LAZ or E57 survey, through the reader the Python package handed in.
Survey read_foreign_survey(const fs::path& path, const SurveyReadSettings& settings) {
  if (!foreign_reader()) {
    detail::fail_in_file(path.string(),
                         "is a LAS/LAZ or E57 survey: these are read by minemap's Python package (laspy, pye57); "
                         "install it (pip install . in minemap's source) and run `python -m minemap map ...`");
  }
  Survey survey = foreign_reader()(path, settings);
  if (survey.scans.empty()) detail::fail_in_file(path.string(), "no scans found", InputProblem::kEmpty);
  return survey;
}
}  // namespace

void set_foreign_survey_reader(ForeignSurveyReader reader) { foreign_reader() = std::move(reader); }

Scan read_scan_file(const fs::path& path, const std::string& format, const ReadSettings& settings) {
  if (format == "uos") return read_uos_points(path, settings);
  if (format == "pcd") return read_pcd(path, settings);
  if (format == "ply") return read_ply(path, settings);
  if (format == "xyz") return read_xyz(path, settings);
  if (format == "kitti") {
    if (path.filename() != "points.bin") return read_kitti_bin(path, settings, 4);
    Scan scan = read_kitti_bin(path, settings, 3);
    scan.name = path.parent_path().filename().string();  // "000002", not "points"
    return scan;
  }
  detail::fail_in_file(path.string(), "is of the survey format '" + format +
                                          "', which the C++ readers do not read (LAS/LAZ and E57: the Python package)");
}

bool is_foreign_survey(const fs::path& path) {
  std::error_code error;
  if (!fs::is_directory(path, error)) return is_foreign_file(path);
  bool foreign = false;
  for (const auto& entry : fs::directory_iterator(path, error)) {
    if (!entry.is_regular_file(error)) continue;
    const fs::path& file = entry.path();
    if (is_foreign_file(file)) {
      foreign = true;
    } else if (uos_scan_number(file.filename().string()) || file.extension() == ".pcd" ||
               file.extension() == ".ply" || (file.extension() == ".bin" && all_digits(file.stem().string()))) {
      return false;  // the native layouts' own checks report a folder of several layouts
    }
  }
  return foreign;
}

std::vector<std::string> ready_scan_names(const fs::path& dir) {
  std::error_code error;
  if (!fs::is_directory(dir, error) || is_foreign_survey(dir)) return {};
  const FolderContent content = list_folder(dir);
  std::vector<std::string> names;
  for (const auto& entry : content.uos) {
    if (!fs::exists(fs::path(entry.second).replace_extension(".pose"), error)) break;
    names.push_back(entry.second.stem().string());
  }
  for (const auto* list : {&content.pcd, &content.ply, &content.xyz, &content.kitti_bin}) {
    for (const fs::path& path : *list) names.push_back(path.stem().string());
  }
  for (const fs::path& folder : content.kitti_xyz_dirs) names.push_back(folder.filename().string());
  return names;
}

Survey read_survey(const fs::path& dir, const SurveyReadSettings& settings) {
  if (settings.initial_poses) {
    std::error_code error;
    if (!fs::exists(*settings.initial_poses, error)) {
      detail::fail_in_file(settings.initial_poses->string(), "missing: the initial poses file does not exist",
                           InputProblem::kInconsistentSurvey);
    }
  }
  Survey survey;
  DroppedPoints dropped;
  std::vector<std::uint64_t> numbers;  // uos / KITTI scan numbers in order, for the gaps warning
  std::string (*name_of)(std::uint64_t) = kitti_stem;
  const ReadSettings& read = settings.read;
  if (is_foreign_survey(dir)) {
    survey = read_foreign_survey(dir, settings);  // LAS/LAZ and E57 stay right-handed, z up
  } else {
    read_native_survey(dir, settings, survey, dropped, numbers, name_of);
    survey.frame_3dtk = survey.format == "uos" || read.right_handed_to_3dtk;
  }
  if (settings.initial_poses) {
    const std::vector<Pose> poses = read_pose_list(*settings.initial_poses, survey.unit, survey.scans.size(), read,
                                                   settings.first_scan, ranged(settings));
    for (std::size_t i = 0; i < poses.size(); ++i) survey.scans[i].pose_cm = poses[i];
  }
  if (settings.reference_poses) {
    survey.truth_cm = read_pose_list(*settings.reference_poses, survey.unit, survey.scans.size(), read,
                                     settings.first_scan, ranged(settings));
  }
  if (survey.format != "las" && survey.format != "laz" && survey.format != "e57") {
    choose_local_origin(survey, settings.origin_cm);  // LAS/LAZ and E57 readers choose their own
  }

  // The survey as a whole, now that every file parsed.
  check_scan_sizes(survey.scans);
  check_duplicate_scans(survey.scans);
  const std::vector<double> diagonals_cm = scan_diagonals_cm(survey.scans);
  check_degenerate_scans(survey.scans, diagonals_cm);
  if (!read.unit && survey.unit == LengthUnit::kCentimetre) check_units(survey.scans, diagonals_cm);
  std::sort(numbers.begin(), numbers.end());
  if (const std::string gaps = describe_gaps(numbers, name_of); !gaps.empty()) {
    survey.warnings.push_back("the scan numbering has gaps: no " + gaps +
                              "; the scans on either side of a gap are matched to each other");
  }
  if (dropped.total > 0) survey.warnings.push_back(describe_dropped(dropped));
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
