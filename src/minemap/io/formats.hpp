#pragma once
// Readers and writers for the formats surveys come in. Every reader throws InputError naming the
// file and the line (text) or byte offset (binary) on truncated, malformed, non-finite, empty or
// absurdly sized input, with InputError::problem() saying which (docs/bad-input.md has the table);
// every writer writes atomically (temp file + rename, core/atomic_file.hpp).
//
// Non-finite coordinates, the same rule for every point reader: a point with a NaN x, y or z is a
// "no return" marker (PCL's convention; 3DTK would read it as a point) and is dropped and counted
// (ReadReport); a scan whose points are all NaN is an error (kNonFinite). An infinite coordinate,
// or one beyond +-1e10 cm (10^5 km; binary garbage read as floats lands there), is an error at its
// line or byte. Pose and trajectory values have no such marker: NaN or inf there is an error.
//
// Units: minemap holds lengths in cm. Each reader takes the file's unit (ReadSettings::unit, with a
// per-format default: cm for 3DTK uos, m for PCD, PLY and KITTI) and converts on load; each writer
// takes the unit to write in.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/core/scan.hpp"
#include "minemap/core/units.hpp"

namespace minemap::io {

namespace fs = std::filesystem;

/// What a reader dropped without failing (ReadSettings::report).
struct ReadReport {
  std::uint64_t nan_points_dropped = 0;  ///< points with a NaN x, y or z (no-return markers)
  std::uint64_t slices_detected = 0;     ///< slices found in scanner order (ReadSettings::detect_slices)
};

/// How to interpret a file's coordinates.
struct ReadSettings {
  std::optional<LengthUnit> unit;  ///< the file's unit; nullopt = the format's default
  /// Convert from a right-handed frame (x forward, y left, z up) into 3DTK's left-handed one
  /// (x right, y up, z forward) as 3DTK's ScanDataTransform_xyz does.
  bool right_handed_to_3dtk = false;
  /// uos files without "# slice" markers: split into slices of this many points (0 = no slices).
  std::uint32_t points_per_slice = 0;
  /// uos files without markers (and no points_per_slice): find the slices from the order of the
  /// points where that is safe (io/slice_detection.hpp), so the paper's slice filter applies.
  bool detect_slices = true;
  /// Refuse files that claim more points than this (absurd headers must not allocate):
  /// InputProblem::kCountBeyondLimits. A count within it that the file is too short to hold is
  /// kTruncated; either way it is checked against the file size before anything is allocated.
  std::uint64_t max_points = 50'000'000;
  /// When set, point readers add what they dropped (NaN points) to it.
  ReadReport* report = nullptr;
  /// The point attributes to keep where the file has them (PointAttribute bits; Scan::attributes).
  /// Mapping keeps the intensity alone (the 3D view colours by it); exports keep every one.
  std::uint8_t attributes = kAllPointAttributes;
};

// ---- 3DTK uos: scanNNN.3d, scanNNN.pose, scanNNN.frames --------------------------------------

/// Reads a `.3d` file: lines "x y z" (or "x y z r", reflectance ignored), '#' comments, up to 10
/// unparsable header lines before the first point (as 3DTK). minemap writes a "# slice N" comment
/// before each slice; when present they restore the slice structure. The pose is NOT read here.
Scan read_uos_points(const fs::path& path, const ReadSettings& settings = {});

/// Writes `scan`'s points (file frame, `unit`) as a `.3d` file with "# slice N" markers.
void write_uos_points(const fs::path& path, const Scan& scan, LengthUnit unit = LengthUnit::kCentimetre);

/// Reads a `.pose` file (x y z in the file's unit, theta_x theta_y theta_z in degrees).
EulerPose read_uos_pose(const fs::path& path, LengthUnit unit = LengthUnit::kCentimetre);
void write_uos_pose(const fs::path& path, const Pose& pose_cm, LengthUnit unit = LengthUnit::kCentimetre);

/// A `.frames` line: the column-major 4x4 transform and 3DTK's algorithm type
/// (0 INVALID, 1 ICP, 2 ICPINACTIVE, 3 LUM, 4 ELCH).
struct FrameLine {
  Pose pose_cm = Pose::Identity();
  int type = 1;
};
std::vector<FrameLine> read_uos_frames(const fs::path& path, LengthUnit unit = LengthUnit::kCentimetre);
void write_uos_frames(const fs::path& path, std::span<const FrameLine> frames, LengthUnit unit = LengthUnit::kCentimetre);

// ---- PCD v0.7 (ascii, binary, binary_compressed with LZF, column-wise) ------------------------

enum class PcdEncoding { kAscii, kBinary, kBinaryCompressed };
Scan read_pcd(const fs::path& path, const ReadSettings& settings = {});
void write_pcd(const fs::path& path, const Scan& scan, PcdEncoding encoding, LengthUnit unit = LengthUnit::kMetre);

// ---- ASCII xyz (.xyz, .asc, .txt: CloudCompare's and PDAL's text export; xyz.cpp) ---------------

/// x y z in metres (right-handed, z up) and optional intensity and colour columns, named by a
/// header line or told by their count (xyz.cpp says how).
Scan read_xyz(const fs::path& path, const ReadSettings& settings = {});
/// Whether a .txt file holds points: its first line names x y z or starts with three numbers (a
/// survey folder's README.txt does not).
bool looks_like_xyz_text(const fs::path& path);

// ---- PLY (ascii, binary_little_endian), vertices x y z --------------------------------------------

Scan read_ply(const fs::path& path, const ReadSettings& settings = {});
/// Writes world-frame points given in cm (e.g. a merged map) as PLY in `unit`.
void write_ply(const fs::path& path, std::span<const Eigen::Vector3f> points_cm, bool binary = true,
               LengthUnit unit = LengthUnit::kMetre);

/// A PLY cloud written batch by batch (binary little-endian), for clouds too large to hold at once:
/// the vertex count is set when it is finished, and the file appears under its name only then
/// (core/atomic_file.hpp: a writer destroyed unfinished leaves nothing). Vertex properties: x y z
/// (float, or double: coordinates far from the origin keep their millimetres), then the attributes
/// of `Layout::attributes` (intensity float, red green blue uchar, time double, ring ushort,
/// return_number uchar), then `scan` (uint) when `scan_index`. Thread-safety: one thread.
class PlyStreamWriter {
 public:
  struct Layout {
    bool double_coordinates = false;
    std::uint8_t attributes = 0;        ///< PointAttribute bits
    bool scan_index = false;
    std::vector<std::string> comments;  ///< one header comment line each (frame, unit, origin)
  };
  PlyStreamWriter(const fs::path& path, Layout layout);
  ~PlyStreamWriter();
  PlyStreamWriter(const PlyStreamWriter&) = delete;
  PlyStreamWriter& operator=(const PlyStreamWriter&) = delete;

  /// Appends `points` (in the file's frame and unit) with their attributes (the layout's columns;
  /// a column `attributes` lacks is written as 0) and scan index.
  void write(std::span<const Eigen::Vector3d> points, const PointAttributes& attributes, std::uint32_t scan = 0);
  std::uint64_t count() const { return count_; }
  /// Sets the vertex count and moves the file under its name.
  void finish();

 private:
  struct File;
  std::unique_ptr<File> file_;
  Layout layout_;
  std::uint64_t count_ = 0;
  std::uint64_t count_offset_ = 0;  ///< where the header's vertex count stands
  std::string buffer_;
};

// ---- KITTI velodyne .bin (float32 x y z [intensity]) ---------------------------------------------

/// `floats_per_point` is 4 for KITTI's raw files (x y z intensity), 3 for xyz-only dumps.
Scan read_kitti_bin(const fs::path& path, const ReadSettings& settings = {}, int floats_per_point = 4);
void write_kitti_bin(const fs::path& path, const Scan& scan, int floats_per_point = 4, LengthUnit unit = LengthUnit::kMetre);

// ---- trajectory files ------------------------------------------------------------------------------

/// Text file of 4x4 matrices (16 numbers each, row-major, blank lines allowed between them).
std::vector<Pose> read_matrix_poses(const fs::path& path, LengthUnit unit = LengthUnit::kMetre);
void write_matrix_poses(const fs::path& path, std::span<const Pose> poses_cm, LengthUnit unit = LengthUnit::kMetre);

/// TUM: "timestamp tx ty tz qx qy qz qw" per line, '#' comments.
struct TimedPose {
  double timestamp_s = 0.0;
  Pose pose_cm = Pose::Identity();
};
std::vector<TimedPose> read_tum(const fs::path& path, LengthUnit unit = LengthUnit::kMetre);
void write_tum(const fs::path& path, std::span<const TimedPose> poses, LengthUnit unit = LengthUnit::kMetre);

/// KITTI poses: 12 numbers per line (3x4 row-major).
std::vector<Pose> read_kitti_poses(const fs::path& path, LengthUnit unit = LengthUnit::kMetre);
void write_kitti_poses(const fs::path& path, std::span<const Pose> poses_cm, LengthUnit unit = LengthUnit::kMetre);

/// gtsam_points-style graph: "vK x y z qx qy qz qw" per line (T_world_lidar). Returns by K.
std::vector<Pose> read_graph_poses(const fs::path& path, LengthUnit unit = LengthUnit::kMetre);

// Additions beyond the original contract (io owner):

/// Writes a graph file in read_graph_poses' format, K = index in `poses_cm`.
void write_graph_poses(const fs::path& path, std::span<const Pose> poses_cm, LengthUnit unit = LengthUnit::kMetre);

/// Which trajectory format a file holds, told apart by its first data line ('#' comments and blank
/// lines skipped): "vK ..." = graph, 8 values = TUM, 12 = KITTI, 4 or 16 = 4x4 matrices.
enum class TrajectoryFormat { kMatrix4x4, kTum, kKitti, kGraph };
TrajectoryFormat detect_trajectory_format(const fs::path& path);

/// Reads any of the trajectory formats above (detect_trajectory_format), poses in file order
/// (graph files: by K); TUM timestamps are dropped.
std::vector<Pose> read_trajectory(const fs::path& path, LengthUnit unit = LengthUnit::kMetre);

// ---- surveys: a folder of scans ----------------------------------------------------------------------

struct SurveyReadSettings {
  ReadSettings read;
  std::optional<fs::path> initial_poses;  ///< TUM, KITTI, 4x4 or graph file; else per-format default
  /// Reference poses for the error report, one per scan in survey order (any survey; replaces
  /// truth/ or graph.txt). Same formats and unit as initial_poses.
  std::optional<fs::path> reference_poses;
  /// Only these scans of the folder, in natural order: [first_scan, first_scan + max_scans) (for
  /// `minemap watch`, which reads scans as they arrive). Pose files (initial_poses, reference_poses,
  /// KITTI's graph.txt) are then indexed by a scan's place in the whole folder and must reach the
  /// range's end. Not for LAS/LAZ and E57 surveys.
  std::size_t first_scan = 0;
  std::size_t max_scans = std::numeric_limits<std::size_t>::max();
  /// The survey's local origin (Survey::origin_cm) when already known: a survey read in parts (a
  /// range, as `minemap watch` reads it) keeps the origin its first part chose.
  std::optional<Eigen::Vector3d> origin_cm;
};

/// A survey loaded from a folder.
struct Survey {
  std::string format;  ///< "uos", "pcd", "ply", "xyz", "kitti"; "las", "laz", "e57" (set_foreign_survey_reader)
  LengthUnit unit = LengthUnit::kCentimetre;  ///< the unit the files were read in (outputs use it)
  std::vector<Scan> scans;                    ///< in natural order of names (full2 before full10); pose_cm = initial guess
  std::optional<std::vector<Pose>> truth_cm;  ///< reference T_world_file per scan, where present
  /// The survey's local frame in the files' frame (cm): file coordinates = world + origin_cm. Zero,
  /// but for surveys in world coordinates (UTM and the like: the first scan stands more than
  /// kWorldCoordinates_cm from the files' origin; LAS/LAZ and E57 choose their own): the files'
  /// frame and the world are then both moved by -origin_cm, a multiple of kLocalOriginGrid_cm (each scan's local
  /// origin, and its poses, truth, initial and reference poses conjugated), so matching, poses and
  /// views stay near zero; outputs are in the local frame, report.json states the origin, and
  /// exports add it back in double.
  Eigen::Vector3d origin_cm = Eigen::Vector3d::Zero();
  /// Warnings for the user, one line each: NaN points dropped, gaps in the numbering.
  std::vector<std::string> warnings;
  /// The scans and poses are in 3DTK's frame (left-handed, y up, z forward): a uos survey, or one
  /// converted by ReadSettings::right_handed_to_3dtk; otherwise the files' own (right-handed, z up).
  /// The outputs a person opens follow it (views, map.laz).
  bool frame_3dtk = false;
};

/// A survey whose first scan stands farther than this from its files' origin is in world
/// coordinates (Survey::origin_cm): 1 km.
inline constexpr double kWorldCoordinates_cm = 100000.0;
/// Local origins (the survey's, and a far scan's anchor before its points become float) are
/// positions rounded to this grid, 100 m, per axis. Rounding is what makes a survey's numbers
/// independent of where its files put it: a copy moved by whole hundreds of metres (a UTM offset,
/// typically) reads to the same floats relative to the same local origin as the original, so it
/// maps to the same local poses bit for bit. Any finer grid (whole metres, whole cm) leaves a
/// residual shift that moves the voxel grid's phase (docs/benchmarks.md, "Surveys in world
/// coordinates").
inline constexpr double kLocalOriginGrid_cm = 10000.0;

/// The fewest points a survey's scan may have (Horn's closed form needs three points).
inline constexpr std::size_t kMinScanPoints = 3;
/// The units check (read_survey): with the unit left to uos' default (cm), a survey whose median
/// scan (of those with at least kUnitCheckMinPoints points) spans less than this diagonal, 5 m, is
/// refused as suspicious (metres read as cm: a mine drive's scans then span 50-200 "cm"; real scans
/// in cm span tens of metres); an explicit ReadSettings::unit skips the check.
inline constexpr double kSuspiciousScanDiagonal_cm = 500.0;
inline constexpr std::size_t kUnitCheckMinPoints = 100;

/// Detects the format and reads every scan. Layouts:
///  - uos: scanNNN.3d (+ scanNNN.pose; missing pose = error), optional truth/scanNNN.pose
///  - pcd / ply: *.pcd / *.ply in natural order of their names (digit runs compare as numbers: full2
///    before full10); initial poses from `initial_poses` or identity
///  - kitti: NNNNNN.bin, or NNNNNN/points.bin (xyz only) with graph.txt as reference poses
/// Every file is parsed first (the first bad file in name order is reported), then the survey is
/// checked as a whole: a scan with fewer than kMinScanPoints points (kEmpty), two scans with the
/// same number or the same points (kInconsistentSurvey), the units check (kSuspiciousUnits). Gaps in
/// the numbering and dropped NaN points are Survey::warnings.
Survey read_survey(const fs::path& dir, const SurveyReadSettings& settings = {});

/// Called with each part of a survey read in parts: its scans (which it may change, and whose points
/// it may free), the index of its first scan and the survey's number of scans. false: read no more.
using SurveyPartConsumer = std::function<bool(std::vector<Scan>& part, std::size_t first, std::size_t total)>;

/// read_survey, `part_scans` files at a time (a long survey's raw points are never all held): each
/// part is parsed (in parallel), given its poses and the survey's local origin, checked alone (too
/// few points, all points identical) and handed to `consume` before the next is read. The survey's
/// scans are returned as `consume` left them. What needs every scan comes after the last part: truth,
/// reference poses, duplicates (files whose points were freed are read again to compare), the units
/// check, the warnings; so a bad file late in the survey is reported after the parts before it were
/// consumed. A consumer that returns false stops the reading: the survey then holds the parts read,
/// unchecked as a whole. LAS/LAZ and E57 surveys come as one part.
Survey read_survey_in_parts(const fs::path& dir, const SurveyReadSettings& settings, std::size_t part_scans,
                            const SurveyPartConsumer& consume);

/// Reads one scan file of a survey of `format` ("uos": a .3d, "pcd", "ply", "kitti": a .bin, or a
/// NNNNNN/points.bin of x y z only) as read_survey reads it: points, slices and attributes, named as
/// read_survey names it; its pose is not read (an export takes it from report.json).
Scan read_scan_file(const fs::path& path, const std::string& format, const ReadSettings& settings = {});

/// The names of a survey folder's complete scans, from the first in natural order (Scan::name, as
/// read_survey names them): uos, a `scanNNN.3d` is complete once its `scanNNN.pose` exists (a
/// scanner writes the pose file last); the other layouts, every scan file under its final name (write
/// it under a temporary name, a leading '.' or a suffix such as `.part`, then rename it). Empty for
/// LAS/LAZ and E57 surveys.
std::vector<std::string> ready_scan_names(const fs::path& dir);

/// Surveys read outside the C++ core: LAS/LAZ (a folder of .las/.laz files) and E57 (an .e57 file,
/// or a folder of them). Their readers are the Python package's (python/minemap/formats.py, on
/// laspy and pye57: one implementation), handed in here when the package loads; read_survey calls
/// it for such a path and checks its survey as any other (initial and reference poses, sizes,
/// duplicates). Without it read_survey refuses such a survey, saying how to read it.
/// Thread-safety: set it before reading (the package sets it on import).
using ForeignSurveyReader = std::function<Survey(const fs::path& path, const SurveyReadSettings& settings)>;
void set_foreign_survey_reader(ForeignSurveyReader reader);
/// An .las/.laz/.e57 file, or a folder holding such files and no scans of the other layouts.
bool is_foreign_survey(const fs::path& path);

/// Writes a survey in uos layout (scanNNN.3d + .pose), and truth/ when given: prepare_uos_folder,
/// write_uos_scans, write_uos_truth in turn.
void write_uos_survey(const fs::path& dir, std::span<const Scan> scans,
                      const std::optional<std::vector<Pose>>& truth_cm = std::nullopt);
/// A survey written a part at a time (a long simulated one): the folder made, and refused (OutputError)
/// where it holds a scan numbered `scan_count` or higher, or truth/ poses when `with_truth` is false.
void prepare_uos_folder(const fs::path& dir, std::size_t scan_count, bool with_truth);
/// Scans numbered first, first + 1, ...: scanNNN.3d and .pose.
void write_uos_scans(const fs::path& dir, std::size_t first, std::span<const Scan> scans);
/// truth/scanNNN.pose for each pose.
void write_uos_truth(const fs::path& dir, std::span<const Pose> truth_cm);

}  // namespace minemap::io
