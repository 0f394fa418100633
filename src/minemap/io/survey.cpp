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
//  - Files are parsed in parallel, a part at a time (read_survey: one part of every file;
//    read_survey_in_parts: `part_scans`), and the first bad file in name order is the one reported.
//    Each part is checked alone (too few points, all points identical); what needs every scan
//    (duplicates, units, truth/) comes after the last part, from per-scan summaries.
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

/// What the checks of the survey as a whole need of a scan, kept after its points may be gone.
struct ScanSummary {
  std::string file;    ///< file_of(scan), for messages
  fs::path parsed;     ///< the file parsed, to read again (empty: a foreign survey's scan)
  std::size_t size = 0;
  double diagonal_cm = 0.0;
  std::uint64_t hash = 0;  ///< of the points' bits and the local origin (points_hash)
};

/// FNV-1a over the points' 32-bit words and the local origin: equal scans hash alike.
std::uint64_t points_hash(const Scan& scan) {
  std::uint64_t hash = 1469598103934665603ull;
  const auto mix = [&hash](const void* data, std::size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t b = 0; b + 4 <= bytes; b += 4) {
      std::uint32_t word;
      std::memcpy(&word, p + b, 4);
      hash = (hash ^ word) * 1099511628211ull;
    }
  };
  mix(scan.points_cm.data(), scan.points_cm.size() * sizeof(Eigen::Vector3f));
  mix(scan.local_origin_cm.data(), 3 * sizeof(double));
  return hash;
}

/// Bounding-box diagonal (cm).
double diagonal_cm(const Scan& scan) {
  if (scan.points_cm.empty()) return 0.0;
  Eigen::Vector3f lo = scan.points_cm.front(), hi = scan.points_cm.front();
  for (const Eigen::Vector3f& p : scan.points_cm) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).cast<double>().norm();
}

/// The checks of one part of the survey, in order (each scan needs kMinScanPoints points; a scan
/// whose points all coincide has no shape to match: named here rather than left to fail as "no
/// overlap"), and its scans' summaries (hash and diagonal in parallel: a pass over every point).
void check_part(const std::vector<Scan>& scans, const std::vector<fs::path>& parsed,
                std::vector<ScanSummary>& summaries) {
  for (const Scan& scan : scans) {
    if (scan.size() >= kMinScanPoints) continue;
    detail::fail_in_file(file_of(scan),
                         "holds only " + std::to_string(scan.size()) + (scan.size() == 1 ? " point" : " points") +
                             "; a scan needs at least " + std::to_string(kMinScanPoints) + " to be registered",
                         InputProblem::kEmpty);
  }
  const std::size_t first = summaries.size();
  summaries.resize(first + scans.size());
  tbb::parallel_for(std::size_t{0}, scans.size(), [&](std::size_t k) {
    ScanSummary& summary = summaries[first + k];
    summary.file = file_of(scans[k]);
    summary.parsed = k < parsed.size() ? parsed[k] : fs::path{};
    summary.size = scans[k].size();
    summary.diagonal_cm = diagonal_cm(scans[k]);
    summary.hash = points_hash(scans[k]);
  });
  for (std::size_t k = 0; k < scans.size(); ++k) {
    if (summaries[first + k].diagonal_cm > 0.0) continue;
    detail::fail_in_file(file_of(scans[k]),
                         "all " + std::to_string(scans[k].size()) +
                             " points are identical: no shape to register (remove the scan, or check its writer)",
                         InputProblem::kEmpty);
  }
}

/// Two scans with exactly the same points are one file copied twice (a real scanner never repeats
/// its noise); matching a scan against its copy would only hide the mistake. Equal hashes are
/// compared point by point: from the scans where both still hold their points, else both files
/// are read again (a survey read in parts lets its points go).
void check_duplicate_scans(const std::vector<ScanSummary>& summaries, const std::vector<Scan>& scans,
                           const std::string& format, const ReadSettings& read) {
  std::map<std::uint64_t, std::size_t> by_hash;
  for (std::size_t i = 0; i < summaries.size(); ++i) {
    const auto [it, inserted] = by_hash.emplace(summaries[i].hash, i);
    if (inserted) continue;
    const std::size_t j = it->second;
    bool same = false;
    if (scans[i].size() == summaries[i].size && scans[j].size() == summaries[j].size) {
      same = scans[j].points_cm == scans[i].points_cm && scans[j].local_origin_cm == scans[i].local_origin_cm;
    } else if (!summaries[i].parsed.empty() && !summaries[j].parsed.empty()) {
      const Scan a = read_scan_file(summaries[j].parsed, format, read), b = read_scan_file(summaries[i].parsed, format, read);
      same = a.points_cm == b.points_cm && a.local_origin_cm == b.local_origin_cm;
    }
    if (same) {
      detail::fail_in_file(summaries[i].file,
                           "holds exactly the same " + std::to_string(summaries[i].size) + " points as " +
                               fs::path(summaries[j].file).filename().string() + " (a copied file?): remove one of them",
                           InputProblem::kInconsistentSurvey);
    }
  }
}

/// The units check (formats.hpp, kSuspiciousScanDiagonal_cm): only for the uos default unit. The
/// median scan is judged, not the largest: one scan seeing 80 m down a drive, read as cm, still
/// spans 80 "cm", and one stray far point must not make a metres survey pass.
void check_units(const std::vector<ScanSummary>& summaries) {
  std::vector<std::size_t> judged;
  for (std::size_t i = 0; i < summaries.size(); ++i) {
    if (summaries[i].size >= kUnitCheckMinPoints) judged.push_back(i);
  }
  if (judged.empty()) return;
  const auto diagonal = [&](std::size_t i) { return summaries[i].diagonal_cm; };
  std::sort(judged.begin(), judged.end(), [&](std::size_t a, std::size_t b) {
    return diagonal(a) < diagonal(b) || (diagonal(a) == diagonal(b) && a < b);
  });
  const std::size_t median = judged[(judged.size() - 1) / 2];
  if (diagonal(median) >= kSuspiciousScanDiagonal_cm) return;
  char extent[96];
  std::snprintf(extent, sizeof extent, "%.3g cm (the largest of the %zu scans: %.3g cm)", diagonal(median),
                judged.size(), diagonal(judged.back()));
  detail::fail_in_file(summaries[median].file,
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

/// A survey in world coordinates is moved near zero (Survey::origin_cm): its origin is `given`, or
/// the first scan's position rounded to kLocalOriginGrid_cm (100 m) when that lies beyond
/// kWorldCoordinates_cm. The files' frame and the world both move by -origin: each scan's points keep
/// their float values (their local origin moves), and each pose T_world_file becomes
/// T(-o) T_world_file T(o), the identity staying the identity, so poses, views and .pose files stay
/// near zero.
Eigen::Vector3d local_origin_for(const Scan& first, const std::optional<Eigen::Vector3d>& given) {
  if (given) return *given;
  const Eigen::Vector3d at = first.world_from_points().block<3, 1>(0, 3);
  if (at.norm() > kWorldCoordinates_cm) return (at / kLocalOriginGrid_cm).array().round().matrix() * kLocalOriginGrid_cm;
  return Eigen::Vector3d::Zero();
}

Pose moved_to_origin(Pose pose, const Eigen::Vector3d& origin) {  // T(-o) * pose * T(o)
  pose.block<3, 1>(0, 3) += pose.block<3, 3>(0, 0) * origin - origin;
  return pose;
}

/// A native survey's files in reading order, and what its layout says of them.
struct NativePlan {
  std::string format;
  LengthUnit unit = LengthUnit::kMetre;
  std::vector<fs::path> paths;
  std::vector<std::uint64_t> numbers;  ///< uos / KITTI scan numbers, for the gaps warning
  std::string (*name_of)(std::uint64_t) = kitti_stem;
};

NativePlan plan_native_survey(const fs::path& dir, const SurveyReadSettings& settings) {
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
  NativePlan plan;
  if (!content.uos.empty()) {
    plan.format = "uos";
    plan.unit = read.unit.value_or(LengthUnit::kCentimetre);
    for (const auto& entry : content.uos) {
      plan.paths.push_back(entry.second);
      plan.numbers.push_back(entry.first);
    }
    plan.name_of = [](std::uint64_t number) { return uos_stem(static_cast<std::size_t>(number)); };
  } else if (!content.pcd.empty() || !content.ply.empty() || !content.xyz.empty()) {
    plan.format = !content.pcd.empty() ? "pcd" : !content.ply.empty() ? "ply" : "xyz";  // a PCD's pose: VIEWPOINT
    plan.unit = read.unit.value_or(LengthUnit::kMetre);
    plan.paths = !content.pcd.empty() ? content.pcd : !content.ply.empty() ? content.ply : content.xyz;
  } else {
    plan.format = "kitti";
    plan.unit = read.unit.value_or(LengthUnit::kMetre);
    plan.paths = content.kitti_bin;
    for (const fs::path& path : content.kitti_bin) plan.numbers.push_back(kitti_number(path));
    for (const fs::path& folder : content.kitti_xyz_dirs) {
      plan.paths.push_back(folder / "points.bin");  // read_scan_file names it by its folder
      plan.numbers.push_back(kitti_number(folder));
    }
    // Both KITTI layouts in one folder would interleave; numbers are only meaningful for one.
    if (!content.kitti_bin.empty() && !content.kitti_xyz_dirs.empty()) plan.numbers.clear();
  }
  return plan;
}

/// What reading the parts gathered for the survey as a whole.
struct PartTally {
  DroppedPoints dropped;
  std::size_t slices_detected = 0;  ///< uos files without '# slice' markers
  std::size_t truth_files = 0;      ///< uos truth/scanNNN.pose files present
  std::vector<ScanSummary> summaries;
};

/// Parses plan.paths[first, first + count) at once (TBB over files: parsing text is most of the
/// reading time); the first bad file in order is the one reported. uos: each scan's .pose file
/// (unless initial poses are given).
std::vector<Scan> read_native_part(const fs::path& dir, const NativePlan& plan, const SurveyReadSettings& settings,
                                   std::size_t first, std::size_t count, PartTally& tally) {
  const std::vector<fs::path> paths(plan.paths.begin() + static_cast<std::ptrdiff_t>(first),
                                    plan.paths.begin() + static_cast<std::ptrdiff_t>(first + count));
  ParallelReads reads(paths, settings.read,
                      [&](const fs::path& p, const ReadSettings& s) { return read_scan_file(p, plan.format, s); });
  std::vector<Scan> scans;
  scans.reserve(paths.size());
  for (std::size_t k = 0; k < paths.size(); ++k) {
    Scan scan = reads.take(k, tally.dropped);
    if (plan.format == "uos") {
      tally.slices_detected += reads.slices_detected(k) > 0 ? 1 : 0;
      if (!settings.initial_poses) {
        const fs::path pose_path = fs::path(paths[k]).replace_extension(".pose");
        if (!fs::exists(pose_path)) {
          detail::fail_in_file(pose_path.string(),
                               "missing: " + paths[k].filename().string() + " needs its pose file (or give initial poses)",
                               InputProblem::kInconsistentSurvey);
        }
        scan.pose_cm = read_pose_file(pose_path, plan.unit, settings.read);
      }
      tally.truth_files += fs::exists(dir / "truth" / (scan.name + ".pose")) ? 1 : 0;
    }
    scans.push_back(std::move(scan));
  }
  return scans;
}

/// A native survey's reference poses of its own: uos truth/ (all or none), KITTI's graph.txt.
std::optional<std::vector<Pose>> native_truth(const fs::path& dir, const NativePlan& plan, const Survey& survey,
                                              const SurveyReadSettings& settings, const PartTally& tally) {
  if (plan.format == "uos" && tally.truth_files > 0) {
    std::vector<Pose> truth;
    for (const Scan& scan : survey.scans) {
      const fs::path truth_path = dir / "truth" / (scan.name + ".pose");
      if (!fs::exists(truth_path)) {
        detail::fail_in_file(truth_path.string(), "missing: truth/ has poses for some scans, so it needs all of them",
                             InputProblem::kInconsistentSurvey);
      }
      truth.push_back(read_pose_file(truth_path, plan.unit, settings.read));
    }
    return truth;
  }
  const fs::path graph = dir / "graph.txt";
  if (plan.format == "kitti" && fs::exists(graph)) {
    return read_pose_list(graph, plan.unit, survey.scans.size(), settings.read, settings.first_scan, ranged(settings));
  }
  return std::nullopt;
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

namespace {

/// read_survey and read_survey_in_parts: `part_scans` scans at a time, each part handed to
/// `consume` (when given) once parsed and checked alone; the survey as a whole checked at the end.
Survey read_in_parts(const fs::path& dir, const SurveyReadSettings& settings, std::size_t part_scans,
                     const SurveyPartConsumer& consume) {
  if (settings.initial_poses) {
    std::error_code error;
    if (!fs::exists(*settings.initial_poses, error)) {
      detail::fail_in_file(settings.initial_poses->string(), "missing: the initial poses file does not exist",
                           InputProblem::kInconsistentSurvey);
    }
  }
  const ReadSettings& read = settings.read;
  Survey survey;
  PartTally tally;
  std::optional<NativePlan> plan;
  std::optional<std::vector<Pose>> initial;
  std::size_t total = 0;
  Survey foreign;
  if (is_foreign_survey(dir)) {
    foreign = read_foreign_survey(dir, settings);  // LAS/LAZ and E57 stay right-handed, z up, their own origin
    survey.format = foreign.format;
    survey.unit = foreign.unit;
    survey.origin_cm = foreign.origin_cm;
    survey.truth_cm = std::move(foreign.truth_cm);
    survey.warnings = std::move(foreign.warnings);
    total = foreign.scans.size();
    part_scans = total;  // read as one
  } else {
    plan = plan_native_survey(dir, settings);
    survey.format = plan->format;
    survey.unit = plan->unit;
    survey.frame_3dtk = survey.format == "uos" || read.right_handed_to_3dtk;
    total = plan->paths.size();
  }
  if (settings.initial_poses) {
    initial = read_pose_list(*settings.initial_poses, survey.unit, total, read, settings.first_scan, ranged(settings));
  }
  const bool native = plan.has_value();
  bool stopped = false;
  for (std::size_t first = 0; first < total && !stopped; first += part_scans) {
    const std::size_t count = std::min(part_scans, total - first);
    std::vector<Scan> part = native ? read_native_part(dir, *plan, settings, first, count, tally)
                                    : std::move(foreign.scans);
    if (native) {  // the next part's files come from the disk while this part is matched
      for (std::size_t k = first + count; k < std::min(total, first + count + part_scans); ++k) {
        detail::prefetch_file(plan->paths[k]);
      }
    }
    if (initial) {
      for (std::size_t k = 0; k < part.size(); ++k) part[k].pose_cm = (*initial)[first + k];
    }
    if (native) {
      if (first == 0) survey.origin_cm = local_origin_for(part.front(), settings.origin_cm);
      if (!survey.origin_cm.isZero()) {
        for (Scan& scan : part) {
          scan.local_origin_cm -= survey.origin_cm;
          scan.pose_cm = moved_to_origin(scan.pose_cm, survey.origin_cm);
        }
      }
    }
    const std::vector<fs::path> parsed =
        native ? std::vector<fs::path>(plan->paths.begin() + static_cast<std::ptrdiff_t>(first),
                                       plan->paths.begin() + static_cast<std::ptrdiff_t>(first + count))
               : std::vector<fs::path>{};
    check_part(part, parsed, tally.summaries);
    if (consume) stopped = !consume(part, first, total);
    for (Scan& scan : part) survey.scans.push_back(std::move(scan));
  }
  if (stopped) return survey;  // an interrupted run: what was read, unchecked as a whole

  // The survey as a whole, now that every file parsed.
  if (native) {
    if (auto truth = native_truth(dir, *plan, survey, settings, tally)) {
      for (Pose& pose : *truth) pose = moved_to_origin(pose, survey.origin_cm);
      survey.truth_cm = std::move(truth);
    }
  }
  if (settings.reference_poses) {
    survey.truth_cm = read_pose_list(*settings.reference_poses, survey.unit, survey.scans.size(), read,
                                     settings.first_scan, ranged(settings));
    if (native) {
      for (Pose& pose : *survey.truth_cm) pose = moved_to_origin(pose, survey.origin_cm);
    }
  }
  check_duplicate_scans(tally.summaries, survey.scans, survey.format, read);
  if (!read.unit && survey.unit == LengthUnit::kCentimetre) check_units(tally.summaries);
  if (tally.slices_detected > 0) {
    // Not a problem; said because it changes what the slice filter does with these files.
    survey.warnings.push_back(std::to_string(tally.slices_detected) + " of " + std::to_string(total) +
                              " uos files have no '# slice' markers: their slices were found from the scanner "
                              "order of the points (--points-per-slice N sets them, --no-slice-detection leaves "
                              "them without)");
  }
  if (native) {
    std::vector<std::uint64_t> numbers = plan->numbers;
    std::sort(numbers.begin(), numbers.end());
    if (const std::string gaps = describe_gaps(numbers, plan->name_of); !gaps.empty()) {
      survey.warnings.push_back("the scan numbering has gaps: no " + gaps +
                                "; the scans on either side of a gap are matched to each other");
    }
  }
  if (tally.dropped.total > 0) survey.warnings.push_back(describe_dropped(tally.dropped));
  return survey;
}

}  // namespace

Survey read_survey(const fs::path& dir, const SurveyReadSettings& settings) {
  return read_in_parts(dir, settings, std::numeric_limits<std::size_t>::max(), {});
}

Survey read_survey_in_parts(const fs::path& dir, const SurveyReadSettings& settings, std::size_t part_scans,
                            const SurveyPartConsumer& consume) {
  if (part_scans == 0) throw std::invalid_argument("read_survey_in_parts: a part holds at least one scan");
  return read_in_parts(dir, settings, part_scans, consume);
}

void prepare_uos_folder(const fs::path& dir, std::size_t scan_count, bool with_truth) {
  std::error_code error;
  fs::create_directories(dir, error);
  if (error) throw OutputError("cannot create " + dir.string() + ": " + error.message());
  // Scans are renumbered 0..n-1. A higher-numbered scan left from an earlier survey would silently
  // join this one when the folder is read back, so it is refused.
  for (const auto& entry : fs::directory_iterator(dir, error)) {
    const auto number = uos_scan_number(entry.path().filename().string());
    if (number && *number >= scan_count) {
      throw OutputError("cannot write a survey of " + std::to_string(scan_count) + " scans into " + dir.string() +
                        ": it already holds " + entry.path().filename().string() + " (use an empty folder)");
    }
  }
  // Likewise a truth/ folder left from an earlier survey would be read back as this one's truth.
  if (!with_truth) {
    for (const auto& entry : fs::directory_iterator(dir / "truth", error)) {
      if (entry.path().extension() == ".pose") {
        throw OutputError("cannot write a survey without truth into " + dir.string() + ": it already holds " +
                          (fs::path("truth") / entry.path().filename()).string() + " (use an empty folder)");
      }
    }
  }
}

void write_uos_scans(const fs::path& dir, std::size_t first, std::span<const Scan> scans) {
  for (std::size_t k = 0; k < scans.size(); ++k) {
    const std::string stem = uos_stem(first + k);
    write_uos_points(dir / (stem + ".3d"), scans[k]);
    write_uos_pose(dir / (stem + ".pose"), scans[k].pose_cm);
  }
}

void write_uos_truth(const fs::path& dir, std::span<const Pose> truth_cm) {
  std::error_code error;
  fs::create_directories(dir / "truth", error);
  if (error) throw OutputError("cannot create " + (dir / "truth").string() + ": " + error.message());
  for (std::size_t i = 0; i < truth_cm.size(); ++i) write_uos_pose(dir / "truth" / (uos_stem(i) + ".pose"), truth_cm[i]);
}

void write_uos_survey(const fs::path& dir, std::span<const Scan> scans, const std::optional<std::vector<Pose>>& truth_cm) {
  if (truth_cm && truth_cm->size() != scans.size()) {
    throw std::invalid_argument("write_uos_survey: " + std::to_string(truth_cm->size()) + " truth poses for " +
                                std::to_string(scans.size()) + " scans");
  }
  prepare_uos_folder(dir, scans.size(), truth_cm.has_value());
  write_uos_scans(dir, 0, scans);
  if (truth_cm) write_uos_truth(dir, *truth_cm);
}

}  // namespace minemap::io
