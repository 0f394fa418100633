#include "minemap/report/survey_export.hpp"

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>

#include <limits>

#include "minemap/filter/deskew.hpp"
#include <set>

#include "minemap/core/error.hpp"
#include "minemap/filter/voxel_filter.hpp"
#include "minemap/io/formats.hpp"

namespace minemap {
namespace {

using json = nlohmann::json;

[[noreturn]] void fail(const std::filesystem::path& path, const std::string& message,
                       InputProblem problem = InputProblem::kMalformed) {
  throw InputError(FileLocation{path.string()}, message, problem);
}

/// report.json's field `key` (an object's member), or a failure naming the file.
const json& field(const json& object, const char* key, const std::filesystem::path& path) {
  if (!object.is_object() || !object.contains(key)) {
    fail(path, std::string("has no \"") + key + "\": not the report.json of a minemap map of this version (map again)");
  }
  return object.at(key);
}

Pose pose_of(const json& rows, double cm_per_unit, const std::filesystem::path& path) {
  Pose pose;
  if (!rows.is_array() || rows.size() != 4) fail(path, "holds a scan pose that is not 4x4");
  for (int r = 0; r < 4; ++r) {
    if (!rows[r].is_array() || rows[r].size() != 4) fail(path, "holds a scan pose that is not 4x4");
    for (int c = 0; c < 4; ++c) {
      if (!rows[r][c].is_number()) fail(path, "holds a scan pose with a value that is not a number");
      pose(r, c) = rows[r][c].get<double>() * (c == 3 && r < 3 ? cm_per_unit : 1.0);
    }
  }
  if (!is_valid_rigid(pose, 1e-6)) fail(path, "holds a scan pose that is not a rigid transform");
  return pose;
}

}  // namespace

std::string describe_attributes(std::uint8_t mask) {
  std::string text;
  const auto add = [&](std::uint8_t bit, const char* name) {
    if (mask & bit) text += (text.empty() ? "" : ", ") + std::string(name);
  };
  add(kIntensity, "intensity");
  add(kColour, "colour");
  add(kTime, "time");
  add(kRing, "ring");
  add(kReturnNumber, "return number");
  return text.empty() ? "none" : text;
}

SurveyExport::SurveyExport(const std::filesystem::path& out_dir, ExportSettings settings)
    : settings_(std::move(settings)), report_path_(out_dir / "report.json") {
  if (!(settings_.voxel_cm >= 0.0) || !std::isfinite(settings_.voxel_cm)) {
    throw std::invalid_argument("the export's voxel size must be a finite length >= 0 cm");
  }
  std::ifstream in(report_path_);
  if (!in) fail(report_path_, "cannot be read: is " + out_dir.string() + " the --out of a finished `minemap map`?");
  const json report = json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (report.is_discarded()) fail(report_path_, "is not valid JSON");
  survey_ = field(report, "survey", report_path_).get<std::string>();
  format_ = field(report, "format", report_path_).get<std::string>();
  if (format_ == "arrays") {
    fail(report_path_, "is the map of scans given as arrays (minemap.map_survey): there are no files to read again",
         InputProblem::kInconsistentSurvey);
  }
  survey_unit_ = parse_length_unit(field(report, "unit", report_path_).get<std::string>());
  survey_3dtk_ = field(report, "frame", report_path_).get<std::string>() == "3dtk";
  const json& settings_json = field(report, "settings", report_path_);
  right_handed_to_3dtk_ = settings_json.value("right_handed_to_3dtk", false);
  const double cm = centimetres_per(survey_unit_);
  if (report.contains("origin")) {
    const auto origin = report["origin"].get<std::vector<double>>();
    if (origin.size() != 3) fail(report_path_, "holds an origin that is not 3 numbers");
    origin_cm_ = Eigen::Vector3d(origin[0], origin[1], origin[2]) * cm;
  }
  output_origin_cm_ = origin_cm_;
  if (report.contains("control")) {  // a map tied to control: its poses are in the grid, less its origin
    const auto origin = field(report["control"], "origin", report_path_).get<std::vector<double>>();
    if (origin.size() != 3) fail(report_path_, "holds a control origin that is not 3 numbers");
    output_origin_cm_ = Eigen::Vector3d(origin[0], origin[1], origin[2]) * cm;
    const json& epsg = report["control"].value("epsg", json(nullptr));
    if (epsg.is_number_unsigned()) epsg_ = epsg.get<std::uint32_t>();
  }
  const std::set<std::string> wanted(settings_.scans.begin(), settings_.scans.end());
  std::set<std::string> found;
  const json& scans = field(report, "scans", report_path_);
  for (std::size_t i = 0; i < scans.size(); ++i) {
    const json& scan = scans[i];
    const std::string name = field(scan, "name", report_path_).get<std::string>();
    const bool registered = field(scan, "registered", report_path_).get<bool>();
    if (!wanted.empty() && !wanted.count(name)) continue;
    found.insert(name);
    if (wanted.empty() && !registered) {  // at its odometry pose: exported only when named
      skipped_.push_back(name);
      continue;
    }
    plan_.push_back({static_cast<std::uint32_t>(i), name, field(scan, "source", report_path_).get<std::string>(),
                     pose_of(field(scan, "pose", report_path_), cm, report_path_),
                     field(scan, "points_in", report_path_).get<std::uint64_t>(), std::nullopt});
    if (scan.contains("sweep_motion")) plan_.back().sweep_motion_cm = pose_of(scan["sweep_motion"], cm, report_path_);
  }
  for (const std::string& name : settings_.scans) {
    if (!found.count(name)) fail(report_path_, "holds no scan " + name + " (--scans)", InputProblem::kInconsistentSurvey);
  }
  if (plan_.empty()) fail(report_path_, "leaves no scan to export", InputProblem::kEmpty);
}

std::uint64_t SurveyExport::points_expected() const {
  std::uint64_t total = 0;
  for (const Planned& scan : plan_) total += scan.points_in;
  return total;
}

std::string SurveyExport::frame_description() const {
  if (settings_.frame == ExportSettings::Frame::kZUp) {
    return std::string("metres, right-handed, z up") + (survey_3dtk_ ? " (turned from the survey's 3DTK frame)" : "");
  }
  return std::string(survey_3dtk_ ? "the survey's 3DTK frame (left-handed, y up)" : "the survey's frame") + ", " +
         to_string(survey_unit_);
}

Eigen::Vector3d SurveyExport::place(const Eigen::Vector3d& world_cm) const {
  const Eigen::Vector3d survey_cm = world_cm + output_origin_cm_;
  if (settings_.frame == ExportSettings::Frame::kSurvey) return survey_cm / centimetres_per(survey_unit_);
  return survey_3dtk_ ? threedtk_to_right_handed(survey_cm, 0.01) : survey_cm / 100.0;
}

Eigen::Vector3d SurveyExport::origin() const {
  return output_origin_cm_.isZero() ? output_origin_cm_ : place(Eigen::Vector3d::Zero());
}

ExportedScan SurveyExport::read(const Planned& planned) const {
  io::ReadSettings read;
  read.unit = survey_unit_;  // as the map read it (the unit it states)
  read.right_handed_to_3dtk = right_handed_to_3dtk_;
  read.detect_slices = false;
  read.attributes = kAllPointAttributes;
  Scan scan = io::read_scan_file(planned.source, format_, read);
  if (scan.size() != planned.points_in) {
    fail(planned.source,
         "holds " + std::to_string(scan.size()) + " points, the map read " + std::to_string(planned.points_in) +
             ": the survey changed since it was mapped (map it again)",
         InputProblem::kInconsistentSurvey);
  }
  ExportedScan out;
  out.index = planned.index;
  out.name = planned.name;
  out.source = planned.source;
  out.points.resize(scan.size());
  // The pose maps the files' frame moved by -origin (io::Survey::origin_cm) into the local world;
  // a sweep the map deskewed is deskewed here too, in that frame, as the map did.
  scan.local_origin_cm -= origin_cm_;
  if (planned.sweep_motion_cm) {
    const SweepTiming timing = sweep_timing(scan, std::numeric_limits<double>::infinity());
    scan.points_cm = deskewed_points(scan, timing, *planned.sweep_motion_cm);
  }
  const Eigen::Matrix3d r = planned.pose_cm.block<3, 3>(0, 0);
  const Eigen::Vector3d t = planned.pose_cm.block<3, 1>(0, 3);
  for (std::size_t i = 0; i < scan.size(); ++i) out.points[i] = place(r * scan.file_point(i) + t);
  out.attributes = std::move(scan.attributes);
  if (settings_.voxel_cm > 0.0) {
    const double voxel = settings_.voxel_cm / centimetres_per(unit());
    const std::vector<std::size_t> kept = voxel_first_points(out.points, voxel);
    std::vector<Eigen::Vector3d> points;
    PointAttributes attributes;
    points.reserve(kept.size());
    const std::uint8_t columns = out.attributes.columns();
    for (const std::size_t k : kept) {
      points.push_back(out.points[k]);
      attributes.push_back(out.attributes.at(k), columns);
    }
    out.points = std::move(points);
    out.attributes = std::move(attributes);
  }
  return out;
}

std::uint8_t SurveyExport::attributes() {
  if (!first_ && next_ < plan_.size()) first_ = read(plan_[next_]);
  return first_ ? first_->attributes.columns() : 0;
}

std::optional<ExportedScan> SurveyExport::next() {
  if (first_) {
    std::optional<ExportedScan> scan = std::move(first_);
    first_.reset();
    ++next_;
    return scan;
  }
  if (next_ >= plan_.size()) return std::nullopt;
  return read(plan_[next_++]);
}

ExportSummary write_export_ply(SurveyExport& scans, const std::filesystem::path& path, const std::function<bool()>& stop,
                               const std::function<void(std::size_t, std::uint64_t)>& progress) {
  ExportSummary summary;
  summary.attributes = scans.attributes();
  io::PlyStreamWriter::Layout layout;
  layout.attributes = summary.attributes;
  layout.scan_index = true;
  layout.double_coordinates = !scans.origin().isZero();  // world coordinates: float would lose millimetres
  layout.comments = {"minemap export of " + scans.survey() + " (" + std::to_string(scans.scans()) + " scans)",
                     "frame: " + scans.frame_description(),
                     "coordinates: the survey's own" + std::string(layout.double_coordinates ? " (world, double)" : ""),
                     "attributes: " + describe_attributes(summary.attributes) + "; scan: the scan's index in report.json"};
  io::PlyStreamWriter ply(path, layout);
  while (std::optional<ExportedScan> scan = scans.next()) {
    if (stop && stop()) return summary;  // the writer, destroyed unfinished, leaves nothing
    const std::uint8_t columns = scan->attributes.columns();
    if (columns != summary.attributes && summary.warnings.size() < 3) {
      summary.warnings.push_back(scan->source + " carries " + describe_attributes(columns) + ", the file's columns are " +
                                 describe_attributes(summary.attributes) + " (missing values are written as 0)");
    }
    ply.write(scan->points, scan->attributes, scan->index);
    ++summary.scans;
    summary.points = ply.count();
    if (progress) progress(summary.scans, summary.points);
  }
  ply.finish();
  summary.completed = true;
  return summary;
}

}  // namespace minemap
