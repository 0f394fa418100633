#include "minemap/report/map_output.hpp"

#include "minemap/slam/control_tie.hpp"

#include <cmath>

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <set>
#include <nlohmann/json.hpp>

#include "minemap/core/atomic_file.hpp"
#include "minemap/core/memory.hpp"
#include "minemap/report/map_html.hpp"
#include "minemap/report/map_views.hpp"

namespace minemap {
namespace {

nlohmann::json pose_json(const Pose& pose_cm, double unit_per_cm) {
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 4; ++r) {
    nlohmann::json row = nlohmann::json::array();
    for (int c = 0; c < 4; ++c) row.push_back(c == 3 && r < 3 ? pose_cm(r, c) * unit_per_cm : pose_cm(r, c));
    rows.push_back(row);
  }
  return rows;
}

nlohmann::json errors_json(const PoseErrors& e, double unit_per_cm) {
  return {{"mean_translation", e.mean_translation_cm * unit_per_cm},
          {"max_translation", e.max_translation_cm * unit_per_cm},
          {"mean_rotation_deg", e.mean_rotation_deg},
          {"max_rotation_deg", e.max_rotation_deg},
          {"mean_relative_translation", e.mean_relative_translation_cm * unit_per_cm},
          {"max_relative_translation", e.max_relative_translation_cm * unit_per_cm},
          {"mean_relative_rotation_deg", e.mean_relative_rotation_deg},
          {"max_relative_rotation_deg", e.max_relative_rotation_deg},
          {"path_length", e.path_length_cm * unit_per_cm},
          {"mean_translation_percent_of_path",
           e.path_length_cm > 0 ? 100.0 * e.mean_translation_cm / e.path_length_cm : 0.0}};
}

/// Each recorded option that changes the poses (or, `changes_poses` false, each that does not) under
/// its keyword name, typed: report.json's "settings" and "run_options".
nlohmann::json settings_json(const std::vector<RecordedSetting>& settings, bool changes_poses) {
  nlohmann::json object = nlohmann::json::object();
  for (const RecordedSetting& setting : settings) {
    if (setting.changes_poses != changes_poses) continue;
    nlohmann::json& value = object[setting.name];
    switch (setting.kind) {
      case RecordedSetting::Kind::kFlag: value = setting.value == "true"; break;
      case RecordedSetting::Kind::kNumber:
      case RecordedSetting::Kind::kNumbers: {
        // Not JSON (inf, nan): kept as the text given.
        const std::string text = setting.kind == RecordedSetting::Kind::kNumber ? setting.value : "[" + setting.value + "]";
        value = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
        if (value.is_discarded()) value = setting.value;
        break;
      }
      case RecordedSetting::Kind::kText:
        value = setting.value.empty() ? nlohmann::json(nullptr) : nlohmann::json(setting.value);
        break;
    }
  }
  return object;
}

}  // namespace

std::optional<TruthComparison> compare_with_truth(const MappingResult& result,
                                                  const std::optional<std::vector<Pose>>& truth_cm) {
  if (!truth_cm || truth_cm->size() != result.scans.size() || result.scans.size() < 2) return std::nullopt;
  std::vector<Pose> initial, registered;
  for (const auto& s : result.scans) {
    initial.push_back(s.initial_pose_cm);
    registered.push_back(s.pose_cm);
  }
  return TruthComparison{pose_errors(initial, *truth_cm), pose_errors(registered, *truth_cm)};
}

std::string map_report(const MappingResult& result, const std::optional<TruthComparison>& truth,
                       const MappingSettings& settings, const MapOutputSettings& output, double write_s) {
  const double unit_per_cm = 1.0 / centimetres_per(output.unit);
  nlohmann::json report;
  report["unit"] = to_string(output.unit);
  report["frame"] = output.survey_in_3dtk_frame ? "3dtk" : "z_up";  // of the poses here, and .frames / .pose
  if (!output.survey.empty()) report["survey"] = output.survey;
  if (!output.format.empty()) report["format"] = output.format;
  if (!output.origin_cm.isZero()) {
    report["origin"] = {output.origin_cm.x() * unit_per_cm, output.origin_cm.y() * unit_per_cm,
                        output.origin_cm.z() * unit_per_cm};
  }
  report["mode"] = to_string(settings.mode);
  report["partial"] = output.survey_scans > result.scans.size();
  report["scans_in_survey"] = std::max(output.survey_scans, result.scans.size());
  report["search"] = to_string(settings.icp.method);
  report["backend"] = result.backend;
  report["backend_choice"] = output.backend_choice;
  report["backend_note"] = result.backend_note;
  report["notes"] = result.notes;
  if (!output.version.empty()) report["version"] = output.version;
  if (!output.command_line.empty()) report["command_line"] = output.command_line;
  if (!output.settings.empty()) {
    report["settings"] = settings_json(output.settings, true);
    report["run_options"] = settings_json(output.settings, false);
  }
  nlohmann::json scans = nlohmann::json::array();
  for (std::size_t i = 0; i < result.scans.size(); ++i) {
    const ScanOutcome& s = result.scans[i];
    scans.push_back({{"name", s.name},
                     {"pose", pose_json(s.pose_cm, unit_per_cm)},
                     {"iterations", s.last_match.iterations()},
                     {"approximate_iterations", s.last_match.approximate_iterations},
                     {"exact_iterations", s.last_match.exact_iterations},
                     {"pairs", s.last_match.pairs},
                     {"rms", s.last_match.rms_cm * unit_per_cm},
                     {"converged", s.registered && s.last_match.converged()},
                     {"registered", s.registered},
                     {"stop", s.registered ? to_string(s.last_match.stop) : s.failure},
                     {"relaxation_matches", s.relaxation_matches},
                     {"points_in", s.points_in},
                     {"points_used", s.points_used},
                     {"outliers_replaced", s.outliers_replaced}});
    if (i < output.sources.size()) scans.back()["source"] = output.sources[i];
    if (std::isfinite(s.stamp_s)) scans.back()["stamp_s"] = s.stamp_s;
    if (s.sweep_motion_cm) scans.back()["sweep_motion"] = pose_json(*s.sweep_motion_cm, unit_per_cm);
    if (s.health.judged) {
      const RegistrationHealth& h = s.health;
      scans.back()["health"] = {{"trusted", !h.doubtful()},
                                {"doubt", h.doubt},
                                {"paired_fraction", h.paired_fraction},
                                {"beyond_bound_fraction", h.beyond_bound_fraction},
                                {"edge_fraction", h.edge_fraction},
                                {"rms", h.rms_cm * unit_per_cm},
                                {"correction", h.correction_cm * unit_per_cm},
                                {"correction_deg", h.correction_deg},
                                {"moved", h.moved_cm * unit_per_cm},
                                {"pair_bound", h.pair_bound_cm * unit_per_cm},
                                {"retry_bound", h.retry_bound_cm * unit_per_cm},
                                {"recovered", h.recovered_inliers > 0},
                                {"recovery_inliers", h.recovered_inliers},
                                {"note", h.note},
                                {"translation_constraint", h.translation_constraint},
                                {"rotation_constraint", h.rotation_constraint},
                                {"judged_after_loop_closure", h.after_loop_closure}};
    }
  }
  report["scans"] = scans;
  nlohmann::json doubtful = nlohmann::json::array();
  for (const std::size_t i : result.doubtful()) doubtful.push_back(result.scans[i].name);
  report["doubtful_scans"] = doubtful;
  report["icp_iterations"] = {{"step1", result.step1_icp_iterations}, {"step3", result.step3_icp_iterations}};
  report["relaxation_matches"] = result.relaxation_matches;
  nlohmann::json loops = nlohmann::json::array();
  for (const LoopClosure& loop : result.loops) {
    loops.push_back({{"from", result.scans[loop.from].name},
                     {"to", result.scans[loop.to].name},
                     {"closed", loop.closed},
                     {"doubt", loop.doubt},
                     {"gap_before", loop.gap_before_cm * unit_per_cm},
                     {"gap_before_deg", loop.gap_before_deg},
                     {"path", loop.path_cm * unit_per_cm},
                     {"misclosure_percent", 100.0 * loop.misclosure_fraction()},
                     {"misclosure_ppm", loop.misclosure_ppm()},
                     {"gap_per_scan", loop.gap_per_scan_cm() * unit_per_cm},
                     {"gap_after", loop.gap_after_cm * unit_per_cm},
                     {"gap_after_deg", loop.gap_after_deg}});
  }
  report["loop_closures"] = loops;
  if (result.control) {
    // A tie to control: the poses above are in the grid, less its origin (in the survey's frame and
    // unit, as "origin" is); origin_grid_m is the same point as east, north, height.
    const ControlTie& tie = *result.control;
    const Eigen::Vector3d grid_m = survey_axes_to_grid(tie.origin_cm, output.survey_in_3dtk_frame) / 100.0;
    nlohmann::json residuals = nlohmann::json::array();
    for (const ControlResidual& r : tie.residuals) {
      nlohmann::json scans_of = nlohmann::json::array();
      for (const std::size_t k : r.scans) scans_of.push_back(result.scans[k].name);
      residuals.push_back({{"point", r.point},
                           {"scans", scans_of},
                           {"east_mm", 1000.0 * r.residual_m.x()},
                           {"north_mm", 1000.0 * r.residual_m.y()},
                           {"height_mm", 1000.0 * r.residual_m.z()},
                           {"distance_mm", 1000.0 * r.residual_m.norm()},
                           {"sigmas", r.sigmas},
                           {"sigma_horizontal_mm", 1000.0 * r.sigma_horizontal_m},
                           {"sigma_vertical_mm", 1000.0 * r.sigma_vertical_m},
                           {"blunder", r.blunder},
                           {"before_tie_mm", {1000.0 * r.before_m.x(), 1000.0 * r.before_m.y(), 1000.0 * r.before_m.z()}}});
    }
    report["control"] = {{"file", tie.file},
                         {"epsg", tie.epsg ? nlohmann::json(*tie.epsg) : nlohmann::json(nullptr)},
                         {"origin", {tie.origin_cm.x() * unit_per_cm, tie.origin_cm.y() * unit_per_cm,
                                     tie.origin_cm.z() * unit_per_cm}},
                         {"origin_grid_m", {grid_m.x(), grid_m.y(), grid_m.z()}},
                         {"points_used", tie.points_used},
                         {"checked_for_blunders", tie.checked_for_blunders},
                         {"rms_mm", 1000.0 * tie.rms_m},
                         {"closure_ppm", tie.closure_ppm},
                         {"drive", tie.drive_cm * unit_per_cm},
                         {"bent_max", tie.bent_max_cm * unit_per_cm},
                         {"bent_mean", tie.bent_mean_cm * unit_per_cm},
                         {"residuals", residuals}};
    nlohmann::json& scans_json = report["scans"];
    for (std::size_t i = 0; i < result.scans.size(); ++i) {
      if (!result.scans[i].covariance) continue;
      const ScanSigma sigma = scan_sigma(result.scans[i]);
      scans_json[i]["sigma"] = {{"axes", {sigma.axes_cm.x() * unit_per_cm, sigma.axes_cm.y() * unit_per_cm,
                                          sigma.axes_cm.z() * unit_per_cm}},
                                {"rotation_deg", sigma.rotation_deg}};
    }
  }
  report["timings_s"] = {{"load", output.load_s},
                         {"filter", result.times.filter_s},
                         {"tree_build", result.times.tree_build_s},
                         {"pairwise", result.times.pairwise_s},
                         {"relaxation", result.times.relaxation_s},
                         {"loop_closure", result.times.loop_closure_s},
                         {"write", write_s}};
  // The cost of each new scan (its match, and the relaxation's share after it), in scan order.
  std::vector<double> per_scan;
  for (const auto& s : result.scans) per_scan.push_back(s.match_s);
  report["timings_s"]["per_scan"] = per_scan;
  if (result.control) report["timings_s"]["control"] = result.times.control_s;
  if (result.times.loop_closure_s > 0.0) {
    report["timings_s"]["loop_closure_parts"] = {{"matches", result.times.loop_matches_s},
                                                 {"pose_graph_steps", result.times.loop_graph_steps_s},
                                                 {"solve", result.times.loop_solve_s},
                                                 {"judging", result.times.loop_judging_s}};
  }
  // The process's memory as each scan was matched, and its peak so far (the writing included).
  std::vector<double> resident;
  for (const auto& s : result.scans) resident.push_back(s.resident_mb);
  report["memory_mb"] = {{"per_scan", resident},
                         {"peak", static_cast<double>(peak_resident_bytes()) / (1024.0 * 1024.0)},
                         {"spilled", static_cast<double>(result.spilled_bytes) / (1024.0 * 1024.0)}};
  if (truth) {
    report["truth"] = {{"odometry", errors_json(truth->odometry, unit_per_cm)},
                       {"registered", errors_json(truth->registered, unit_per_cm)}};
  }
  return report.dump(2) + "\n";
}

namespace {

/// A tied scan's sigma in words, for map.html's info box.
std::string sigma_text(const ScanSigma& sigma) {
  char text[120];
  std::snprintf(text, sizeof text, "%.1f x %.1f x %.1f cm, %.3f deg", sigma.axes_cm.x(), sigma.axes_cm.y(),
                sigma.axes_cm.z(), sigma.rotation_deg);
  return text;
}

/// The map as the person-facing pictures show it: metres, right-handed, z up (MapOutputSettings).
/// Points and positions stay in cm here (the views and map.html take cm); only the frame turns.
/// The points are a sample when the map has more than MapOutputSettings::picture_points_max.
struct PersonView {
  std::vector<Eigen::Vector3f> points_cm;        ///< every scan's used points (or every k-th), placed
  std::vector<float> intensity;                  ///< one per point when every scan has them, else empty
  std::vector<std::uint32_t> point_scans;        ///< each point's scan
  std::vector<Eigen::Vector3d> positions_cm, reference_positions_cm;
  std::vector<io::TimedPose> trajectory_cm;      ///< T_world_scan in the person frame (cm)
  std::vector<report::MapHtmlScan> html_scans;
  bool every_scan_has_intensity = true;          ///< (so map.ply carries it)
};

Pose person_pose(const Pose& pose_cm, bool from_3dtk) {
  return from_3dtk ? threedtk_pose_to_right_handed(pose_cm, 1.0) : pose_cm;
}

/// Scan i's map points placed in the person frame, every `stride`-th (cm, float: as map.ply stores them).
void place_points(const MappingResult& result, std::size_t i, bool from_3dtk, std::size_t stride,
                  std::vector<Eigen::Vector3f>& placed, const MapPoints& points) {
  const Pose pose = person_pose(result.scans[i].world_from_points, from_3dtk);
  const Eigen::Matrix3d r = pose.block<3, 3>(0, 0);
  const Eigen::Vector3d t = pose.block<3, 1>(0, 3);
  if (!points.points_cm) return;
  const std::vector<Eigen::Vector3f>& local = *points.points_cm;
  for (std::size_t k = 0; k < local.size(); k += stride) placed.push_back((r * local[k].cast<double>() + t).cast<float>());
}

bool has_intensity(const MapPoints& points) {
  return points.intensity && points.points_cm && points.intensity->size() == points.points_cm->size();
}

PersonView person_view(const MappingResult& result, const std::optional<std::vector<Pose>>& truth_cm,
                       bool from_3dtk, std::size_t picture_points_max) {
  const auto turn = [from_3dtk](const Eigen::Vector3d& p_cm) {
    return from_3dtk ? threedtk_to_right_handed(p_cm, 1.0) : p_cm;
  };
  PersonView view;
  std::size_t total = 0;
  for (const ScanOutcome& scan : result.scans) total += scan.points_used;
  // Every k-th point of each scan above the bound; sized once (a long survey's map is millions of
  // points, and growing by doubling held twice that).
  const std::size_t stride = picture_points_max > 0 && total > picture_points_max
                                 ? (total + picture_points_max - 1) / picture_points_max
                                 : 1;
  view.points_cm.reserve(total / stride + result.scans.size());
  view.point_scans.reserve(total / stride + result.scans.size());
  view.every_scan_has_intensity = !result.scans.empty();
  for (std::size_t i = 0; i < result.scans.size(); ++i) {
    const ScanOutcome& scan = result.scans[i];
    view.trajectory_cm.push_back({static_cast<double>(i), person_pose(scan.pose_cm, from_3dtk)});
    view.positions_cm.push_back(turn(scan.pose_cm.block<3, 1>(0, 3)));
    const MapPoints points = result.map_points(i);  // one scan at a time (read back where spilled)
    place_points(result, i, from_3dtk, stride, view.points_cm, points);
    if (view.every_scan_has_intensity && has_intensity(points)) {
      for (std::size_t k = 0; k < points.intensity->size(); k += stride) view.intensity.push_back((*points.intensity)[k]);
    } else {
      view.every_scan_has_intensity = false;
    }
    view.point_scans.resize(view.points_cm.size(), static_cast<std::uint32_t>(i));
    // map.html's info box: why a registered scan's match is doubtful, or why an unregistered one
    // failed; for a trusted one that needed a retry, from how wide.
    std::string note = scan.health.note;
    if (note.empty() && scan.registered && !scan.health.doubtful() && scan.health.recovered_inliers > 0) {
      char text[200];
      std::snprintf(text, sizeof text,
                    "trusted after a recovery: the match from the motion model's start was not, so the scan was "
                    "registered without a start (FPFH features, RANSAC: %zu pairs agreed) and matched from there",
                    scan.health.recovered_inliers);
      note = text;
    } else if (note.empty() && scan.registered && !scan.health.doubtful() && scan.health.retry_bound_cm > 0.0f) {
      char text[160];
      std::snprintf(text, sizeof text,
                    "trusted after a retry from %g cm: the match at the %g cm bound started out of its reach",
                    double(scan.health.retry_bound_cm), double(scan.health.pair_bound_cm));
      note = text;
    }
    const bool tied = scan.covariance.has_value();  // a map tied to control: the scan's sigma
    const ScanSigma sigma = tied ? scan_sigma(scan) : ScanSigma{};
    view.html_scans.push_back({.name = scan.name,
                               .position_cm = view.positions_cm.back(),
                               .iterations = scan.last_match.iterations(),
                               .pairs = scan.last_match.pairs,
                               .rms_cm = scan.last_match.rms_cm,
                               .registered = scan.registered,
                               .doubt = !scan.registered         ? scan.failure
                                        : scan.health.doubtful() ? scan.health.doubt
                                                                 : "",
                               .note = note,
                               .sigma = tied ? sigma_text(sigma) : "",
                               .sigma_cm = tied ? sigma.axes_cm.maxCoeff() : 0.0});
  }
  if (!view.every_scan_has_intensity) std::vector<float>().swap(view.intensity);
  if (truth_cm && truth_cm->size() == result.scans.size()) {
    // Reference trajectory expressed in the master scan's frame, as the registered one is.
    const Pose align = result.scans.front().pose_cm * rigid_inverse(truth_cm->front());
    for (const auto& pose : *truth_cm) view.reference_positions_cm.push_back(turn((align * pose).block<3, 1>(0, 3)));
  }
  return view;
}

/// map.ply: the registered points the matching used, in metres, right-handed, z up, with each
/// point's scan and (where every scan has one) its intensity. Scan by scan, read back where spilled:
/// never the whole map in memory.
void write_map_ply(const std::filesystem::path& path, const MappingResult& result, bool with_intensity,
                   const MapOutputSettings& output) {
  io::PlyStreamWriter::Layout layout;
  layout.attributes = with_intensity ? kIntensity : 0;
  layout.scan_index = true;
  layout.comments = {"minemap map: the registered points the matching used (voxel means or filtered slices)",
                     "frame: metres, right-handed, z up" + std::string(output.survey_in_3dtk_frame
                                                                           ? " (turned from the survey's 3DTK frame)"
                                                                           : "")};
  if (result.control) {
    const Eigen::Vector3d grid = survey_axes_to_grid(result.control->origin_cm, output.survey_in_3dtk_frame) / 100.0;
    char text[200];
    std::snprintf(text, sizeof text, "grid: add the origin %.3f %.3f %.3f m (east north height; report.json control)",
                  grid.x(), grid.y(), grid.z());
    layout.comments.push_back(text);
    if (result.control->epsg) layout.comments.push_back("crs: EPSG:" + std::to_string(*result.control->epsg));
  } else if (!output.origin_cm.isZero()) {
    const Eigen::Vector3d origin = output.origin_cm / 100.0;
    layout.comments.push_back("local frame: add the survey's origin " + std::to_string(origin.x()) + " " +
                              std::to_string(origin.y()) + " " + std::to_string(origin.z()) +
                              " m (report.json) for its own coordinates");
  }
  io::PlyStreamWriter ply(path, layout);
  std::vector<Eigen::Vector3f> placed;
  std::vector<Eigen::Vector3d> points;
  PointAttributes attributes;
  for (std::size_t i = 0; i < result.scans.size(); ++i) {
    const MapPoints scan_points = result.map_points(i);
    placed.clear();
    place_points(result, i, output.survey_in_3dtk_frame, 1, placed, scan_points);
    if (placed.empty()) continue;
    points.clear();
    for (const Eigen::Vector3f& p : placed) points.push_back(p.cast<double>() / 100.0);
    if (with_intensity) attributes.intensity = *scan_points.intensity;
    ply.write(points, attributes, static_cast<std::uint32_t>(i));
  }
  ply.finish();
}

/// The scans an earlier run wrote to `out_dir` (its report.json), or none: read before this run
/// overwrites it, so that run's .pose/.frames files can be told from this one's.
std::vector<std::string> earlier_scan_names(const std::filesystem::path& out_dir) {
  std::vector<std::string> names;
  std::ifstream in(out_dir / "report.json");
  if (!in) return names;
  const nlohmann::json report = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (!report.is_object() || !report.contains("scans") || !report["scans"].is_array()) return names;
  for (const auto& scan : report["scans"]) {
    if (scan.is_object() && scan.contains("name") && scan["name"].is_string()) names.push_back(scan["name"]);
  }
  return names;
}

/// Removes the .pose/.frames files an earlier run wrote for scans this run does not have (a 64-scan
/// map's scan063.pose beside a 6-scan survey's outputs would be loaded by 3DTK's `show`). Only
/// names the earlier report.json lists are touched: nothing minemap did not write.
void remove_earlier_scan_files(const std::filesystem::path& out_dir, const std::vector<std::string>& earlier,
                               const MappingResult& result) {
  std::set<std::string> current;
  for (const ScanOutcome& scan : result.scans) current.insert(scan.name);
  for (const std::string& name : earlier) {
    if (current.count(name) != 0 || name.find('/') != std::string::npos || name.empty()) continue;
    std::error_code ignored;
    std::filesystem::remove(out_dir / (name + ".pose"), ignored);
    std::filesystem::remove(out_dir / (name + ".frames"), ignored);
  }
}

}  // namespace

std::string write_map_outputs(const std::filesystem::path& out_dir, const MappingResult& result,
                              const std::optional<std::vector<Pose>>& truth_cm,
                              const std::optional<TruthComparison>& truth, const MappingSettings& settings,
                              const MapOutputSettings& output) {
  const auto start = std::chrono::steady_clock::now();
  std::filesystem::create_directories(out_dir);
  const std::vector<std::string> earlier = earlier_scan_names(out_dir);
  // 3DTK's own files stay in the survey's frame and unit, for 3DTK's tools. Files that do not depend
  // on each other are written in parallel (each one atomically); the first failure propagates as it
  // would from a serial loop.
  tbb::parallel_for(std::size_t{0}, result.scans.size(), [&](std::size_t i) {
    const ScanOutcome& scan = result.scans[i];
    io::write_uos_frames(out_dir / (scan.name + ".frames"), scan.frames, output.unit);
    io::write_uos_pose(out_dir / (scan.name + ".pose"), scan.pose_cm, output.unit);
  });
  // What a person opens: metres, right-handed, z up.
  const PersonView view = person_view(result, truth_cm, output.survey_in_3dtk_frame, output.picture_points_max);
  report::MapViewSettings views;
  views.up_axis = 2;
  views.title = output.title;
  const report::MapViewInput input{view.points_cm, view.positions_cm, view.reference_positions_cm};
  report::MapHtmlSettings html;
  html.up_axis = 2;
  html.unit = LengthUnit::kMetre;
  html.title = output.title;
  tbb::parallel_invoke(
      [&] {
        io::write_tum(out_dir / "trajectory.tum", view.trajectory_cm, LengthUnit::kMetre);
        write_map_ply(out_dir / "map.ply", result, view.every_scan_has_intensity, output);
      },
      [&] { report::write_top_view_png(out_dir / "top.png", input, views); },
      [&] { report::write_side_view_png(out_dir / "side.png", input, views); },
      [&] {
        report::write_map_html(out_dir / "map.html", {view.points_cm, view.point_scans, view.html_scans, view.intensity},
                               html);
      });

  const double write_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const std::string text = map_report(result, truth, settings, output, write_s);
  write_file_atomically(out_dir / "report.json", text);
  remove_earlier_scan_files(out_dir, earlier, result);
  return text;
}

}  // namespace minemap
