#pragma once
// The registered survey as a user takes it away (`minemap export OUT --to FILE`): every point of
// every scan, with every attribute its file carries and its scan index, placed by the poses of a
// finished map (OUT/report.json), in metres, right-handed, z up (or the survey's own frame), in the
// survey's own coordinates (its local origin added back, in double).
//
// Streamed: SurveyExport re-reads the survey one scan at a time (io::read_scan_file, as the map
// read it) and hands out each scan's placed points; nothing of a scan is kept once the next is
// asked for, so memory does not grow with the survey. Writers take the scans in turn: PLY here
// (write_export_ply), LAS/LAZ, COPC and E57 in the Python package (python/minemap/export.py), which
// reads the same stream.
//
// Never silently wrong: a report.json that is not a finished map's, a scan file that is gone or now
// holds another point count than the map read, are InputErrors naming the file.
//
// Thread-safety: one thread at a time.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/core/scan.hpp"
#include "minemap/core/units.hpp"

namespace minemap {

/// What to export and in which frame.
struct ExportSettings {
  /// kZUp: metres, right-handed, z up (a uos survey's 3DTK frame turned). kSurvey: the survey's own
  /// frame and unit (3DTK's left-handed, y-up cm for uos), as its files and report.json are.
  enum class Frame { kZUp, kSurvey };
  Frame frame = Frame::kZUp;
  /// > 0: each scan thinned to the first of its points in each cube of this size (cm), which keeps
  /// real points with their own attributes. 0: every point.
  double voxel_cm = 0.0;
  /// Only these scans (names, in survey order). Empty: every registered scan.
  std::vector<std::string> scans;
};

/// One scan, placed.
struct ExportedScan {
  std::uint32_t index = 0;  ///< its index in the survey (report.json's scans)
  std::string name;
  std::string source;
  std::vector<Eigen::Vector3d> points;  ///< in the export's frame and unit, world coordinates
  PointAttributes attributes;           ///< of those points, as the file carries them
};

class SurveyExport {
 public:
  /// Reads `out_dir`/report.json and plans the export. Throws InputError naming report.json when it
  /// is not a finished map's (or names a scan it does not hold), std::invalid_argument for settings.
  SurveyExport(const std::filesystem::path& out_dir, ExportSettings settings);

  /// The next scan, read and placed; empty after the last.
  std::optional<ExportedScan> next();

  std::size_t scans() const { return plan_.size(); }  ///< scans to export
  std::uint64_t points_expected() const;              ///< Σ points_in of those scans (before thinning)
  /// The unit and frame of the points handed out, in words for a file's header.
  std::string frame_description() const;
  LengthUnit unit() const { return settings_.frame == ExportSettings::Frame::kZUp ? LengthUnit::kMetre : survey_unit_; }
  /// The survey's origin in the export's frame and unit (zero: the survey was not in world coordinates).
  Eigen::Vector3d origin() const;
  /// The attributes of the first scan (a writer's columns), read without placing its points.
  std::uint8_t attributes();
  const std::string& survey() const { return survey_; }
  /// The grid's EPSG code of a map tied to control (report.json control.epsg), when it names one.
  std::optional<std::uint32_t> epsg() const { return epsg_; }
  /// Scans of the map left out: unregistered ones, which hold their odometry pose (unless named).
  const std::vector<std::string>& skipped() const { return skipped_; }

 private:
  struct Planned {
    std::uint32_t index;
    std::string name, source;
    Pose pose_cm;  ///< T_world_file, survey frame, cm
    std::uint64_t points_in;
    /// The motion the map deskewed the sweep by (report.json's sweep_motion; filter/deskew.hpp).
    std::optional<Pose> sweep_motion_cm;
  };
  Eigen::Vector3d place(const Eigen::Vector3d& world_cm) const;
  ExportedScan read(const Planned& scan) const;

  ExportSettings settings_;
  std::filesystem::path report_path_;
  std::string survey_, format_;
  LengthUnit survey_unit_ = LengthUnit::kCentimetre;
  bool survey_3dtk_ = false;
  bool right_handed_to_3dtk_ = false;
  Eigen::Vector3d origin_cm_ = Eigen::Vector3d::Zero();         ///< the files' local frame (report "origin")
  Eigen::Vector3d output_origin_cm_ = Eigen::Vector3d::Zero();  ///< the poses' (a control tie's grid origin)
  std::optional<std::uint32_t> epsg_;
  std::vector<Planned> plan_;
  std::vector<std::string> skipped_;
  std::size_t next_ = 0;
  std::optional<ExportedScan> first_;  ///< read ahead by attributes()
};

/// Writes `scans` to a binary PLY at `path` (temp + rename), every attribute of the first scan and
/// the scan index as properties, double coordinates when the survey is in world coordinates.
/// `stop` is asked between scans: true abandons the file (nothing is left) and returns false.
/// `progress(scans done, points written)` after each scan.
struct ExportSummary {
  std::size_t scans = 0;
  std::uint64_t points = 0;
  std::uint8_t attributes = 0;
  bool completed = false;
  std::vector<std::string> warnings;
};
ExportSummary write_export_ply(SurveyExport& scans, const std::filesystem::path& path,
                               const std::function<bool()>& stop = {},
                               const std::function<void(std::size_t, std::uint64_t)>& progress = {});

/// "intensity, colour, time" for the attributes of `mask`.
std::string describe_attributes(std::uint8_t mask);

}  // namespace minemap
