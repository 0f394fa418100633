#include "minemap/io/control.hpp"

#include <cstdio>
#include <map>
#include <ostream>
#include <set>

#include "minemap/core/atomic_file.hpp"
#include "minemap/io/text_reader.hpp"

namespace minemap::io {
namespace {

using detail::LineReader;

/// What each record holds, for the messages.
constexpr const char* kPointForm = "point NAME E N H SIGMA [SIGMA_VERTICAL] (metres)";
constexpr const char* kStationForm = "station SCAN POINT [INSTRUMENT_HEIGHT_M]";
constexpr const char* kTargetForm = "target SCAN POINT X Y Z (metres, in the scan file's frame)";

/// The point an observation names, resolved once every point is read.
struct PendingName {
  std::string name;
  std::int64_t line;
};

}  // namespace

ControlFile read_control(const std::filesystem::path& path) {
  ControlFile control;
  control.path = path.string();
  const std::string text = detail::read_file_bytes(path);
  LineReader reader(text, control.path);
  std::map<std::string, std::size_t> point_index;
  std::vector<PendingName> observed;  // observations[i]'s point, by name
  std::string_view tokens[8];
  std::string_view line;
  while (reader.next(line)) {
    const std::string_view content = detail::strip_comment(line);
    if (detail::is_blank(content)) continue;
    const std::size_t count = detail::split_tokens(content, tokens);
    const std::string_view record = tokens[0];
    const auto expect = [&](std::size_t least, std::size_t most, const char* form) {
      if (count < least || count > most) {
        const std::string message = std::string(record) + " takes " +
                                    (least == most ? std::to_string(least - 1)
                                                   : std::to_string(least - 1) + " or " + std::to_string(most - 1)) +
                                    " values, found " + std::to_string(count - 1) + ": " + form;
        if (count < least) reader.fail_short_line(message);
        reader.fail(message);
      }
    };
    if (record == "crs") {
      expect(2, 2, "crs EPSG_CODE");
      if (control.epsg) reader.fail("a second crs line (the grid has one coordinate reference system)");
      std::string_view code = tokens[1];
      if (code.size() > 5 && (code.substr(0, 5) == "EPSG:" || code.substr(0, 5) == "epsg:")) code.remove_prefix(5);
      std::uint64_t value = 0;
      if (!detail::parse_uint64(code, value) || value == 0 || value > 999999) {
        reader.fail("crs " + detail::quoted(tokens[1]) + " is not an EPSG code (a number such as 32633)");
      }
      control.epsg = static_cast<std::uint32_t>(value);
    } else if (record == "point") {
      expect(6, 7, kPointForm);
      double values[5] = {0, 0, 0, 0, 0};
      detail::parse_finite_values(reader, std::span(tokens + 2, count - 2), std::span(values, count - 2), "point");
      ControlPoint point;
      point.name = std::string(tokens[1]);
      point.grid_m = {values[0], values[1], values[2]};
      point.sigma_horizontal_m = values[3];
      point.sigma_vertical_m = count == 7 ? values[4] : values[3];
      point.line = reader.line_number();
      if (!(point.sigma_horizontal_m > 0.0) || !(point.sigma_vertical_m > 0.0)) {
        reader.fail("point " + point.name + ": a sigma must be more than 0 m (a known point is known to some mm)");
      }
      if (const auto found = point_index.find(point.name); found != point_index.end()) {
        reader.fail("point " + point.name + " is defined twice (first on line " +
                    std::to_string(control.points[found->second].line) + ")", InputProblem::kInconsistentSurvey);
      }
      point_index.emplace(point.name, control.points.size());
      control.points.push_back(std::move(point));
    } else if (record == "station" || record == "target") {
      const bool station = record == "station";
      if (station) {
        expect(3, 4, kStationForm);
      } else {
        expect(6, 6, kTargetForm);
      }
      ControlObservation observation;
      observation.kind = station ? ControlObservation::Kind::kStation : ControlObservation::Kind::kTarget;
      observation.scan = std::string(tokens[1]);
      observation.line = reader.line_number();
      double values[3] = {0, 0, 0};
      const std::size_t numbers = count - 3;
      detail::parse_finite_values(reader, std::span(tokens + 3, numbers), std::span(values, numbers), std::string(record));
      if (station) {
        observation.instrument_height_cm = 100.0 * values[0];
      } else {
        observation.in_scan_cm = 100.0 * Eigen::Vector3d(values[0], values[1], values[2]);
      }
      observed.push_back({std::string(tokens[2]), reader.line_number()});
      control.observations.push_back(std::move(observation));
    } else {
      reader.fail("unknown record " + detail::quoted(record) + ": a control file holds crs, point, station and target "
                  "lines ('#' starts a comment)");
    }
  }
  for (std::size_t i = 0; i < observed.size(); ++i) {
    const auto found = point_index.find(observed[i].name);
    if (found == point_index.end()) {
      detail::fail_at_line(control.path, observed[i].line,
                           "observes point " + observed[i].name + ", which no point line defines",
                           InputProblem::kInconsistentSurvey);
    }
    control.observations[i].point = found->second;
  }
  if (control.observations.empty()) {
    detail::fail_in_file(control.path, "holds no station or target line: no scan observes a control point",
                         InputProblem::kEmpty);
  }
  return control;
}

void check_control_scans(const ControlFile& control, std::span<const std::string> scan_names) {
  const std::set<std::string_view> names(scan_names.begin(), scan_names.end());
  for (const ControlObservation& observation : control.observations) {
    if (!names.contains(observation.scan)) {
      detail::fail_at_line(control.path, observation.line,
                           "names scan " + observation.scan + ", which the survey does not hold",
                           InputProblem::kInconsistentSurvey);
    }
  }
}

void write_control(const std::filesystem::path& path, const ControlFile& control, std::span<const std::string> comment) {
  write_file_atomically(path, [&](std::ostream& out) {
    char text[256];
    for (const std::string& line : comment) out << "# " << line << '\n';
    if (control.epsg) out << "crs " << *control.epsg << '\n';
    for (const ControlPoint& point : control.points) {
      std::snprintf(text, sizeof text, "point %s %.4f %.4f %.4f %.4f %.4f\n", point.name.c_str(), point.grid_m.x(),
                    point.grid_m.y(), point.grid_m.z(), point.sigma_horizontal_m, point.sigma_vertical_m);
      out << text;
    }
    for (const ControlObservation& observation : control.observations) {
      const std::string& point = control.points.at(observation.point).name;
      if (observation.kind == ControlObservation::Kind::kStation) {
        std::snprintf(text, sizeof text, "station %s %s %.4f\n", observation.scan.c_str(), point.c_str(),
                      observation.instrument_height_cm / 100.0);
      } else {
        const Eigen::Vector3d p = observation.in_scan_cm / 100.0;
        std::snprintf(text, sizeof text, "target %s %s %.4f %.4f %.4f\n", observation.scan.c_str(), point.c_str(),
                      p.x(), p.y(), p.z());
      }
      out << text;
    }
  });
}

}  // namespace minemap::io
