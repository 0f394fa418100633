// minemap._core: the C++ core as a Python extension (pybind11). The public API is the package's
// python/minemap/__init__.py; this module is its thin layer:
//  * settings arrive as `minemap map` option lists (the package turns keyword arguments into them)
//    and are parsed by the command line's own definitions (cli.hpp): names, defaults, checks once;
//  * points arrive as numpy (N, 3) float32/float64 arrays of any strides, read in place (no copy of
//    the array; each point goes once into the Scan's float-cm storage) and checked: shape, dtype,
//    NaN/inf and size errors are ValueErrors naming the argument and the point;
//  * the GIL is released while C++ works; Ctrl-C is seen between scans (map_survey) as the command
//    line sees it, and arrives as KeyboardInterrupt;
//  * C++ errors arrive as the command line's messages: InputError (a ValueError: file and line or
//    byte), BackendError (RuntimeError), OutputError (OSError); bad settings as ValueError.
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "minemap/backend/make_backend.hpp"
#include "minemap/cli/cli.hpp"
#include "minemap/cli/exit_codes.hpp"
#include "minemap/core/error.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/io/scan_builder.hpp"
#include "minemap/registration/health.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/report/map_output.hpp"
// Internal (not installed): the matcher's reduction and registration of one scan, which register() shares.
#include "minemap/slam/scan_preparation.hpp"
#include "minemap/slam/scan_registration.hpp"

namespace py = pybind11;
using namespace minemap;

namespace {

// ---- numpy <-> C++ --------------------------------------------------------------------------------

/// Reads an (N, 3) float array in place into a Scan (cm, float relative to a local origin, through
/// the readers' own ScanBuilder). `what` names the argument in errors.
template <typename T>
void add_points(io::detail::ScanBuilder& builder, const py::array& array, const std::string& what) {
  const auto view = array.unchecked<T, 2>();
  const py::ssize_t n = view.shape(0);
  builder.reserve(static_cast<std::size_t>(n));
  for (py::ssize_t i = 0; i < n; ++i) {
    const double x = view(i, 0), y = view(i, 1), z = view(i, 2);
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      throw py::value_error(what + ": point " + std::to_string(i) + " is not finite (" + std::to_string(x) + ", " +
                            std::to_string(y) + ", " + std::to_string(z) + ")");
    }
    if (const auto result = builder.add(x, y, z); result != io::detail::ScanBuilder::AddResult::kOk) {
      throw py::value_error(what + ": point " + std::to_string(i) + ": " + builder.describe(result));
    }
  }
}

py::array checked_points(const py::handle& object, const std::string& what) {
  if (!py::isinstance<py::array>(object)) {
    throw py::value_error(what + ": expected a numpy array of shape (N, 3), got " +
                          std::string(py::str(py::type::of(object).attr("__name__"))));
  }
  py::array array = py::reinterpret_borrow<py::array>(object);
  if (array.ndim() != 2 || array.shape(1) != 3) {
    const std::string shape = py::str(py::tuple(array.attr("shape")));
    throw py::value_error(what + ": expected an array of shape (N, 3), got shape " + shape);
  }
  if (!array.dtype().is(py::dtype::of<float>()) && !array.dtype().is(py::dtype::of<double>())) {
    throw py::value_error(what + ": expected float32 or float64 points, got dtype " +
                          std::string(py::str(array.dtype())));
  }
  if (static_cast<std::size_t>(array.shape(0)) < io::kMinScanPoints) {
    throw py::value_error(what + ": " + std::to_string(array.shape(0)) + " points; a scan needs at least " +
                          std::to_string(io::kMinScanPoints));
  }
  return array;
}

/// A scan from an (N, 3) array in `unit`; `slice_offsets` (optional, S+1 ascending offsets from 0
/// to N) keep a scanner's slices for the paper's slice filter.
Scan scan_from_array(const py::handle& points, const std::string& name, const std::string& source, LengthUnit unit,
                     const py::object& slice_offsets = py::none()) {
  const py::array array = checked_points(points, source);
  io::ReadSettings read;
  read.unit = unit;
  read.detect_slices = false;
  io::detail::ScanBuilder builder(source, read, unit);
  std::vector<std::size_t> starts;
  if (!slice_offsets.is_none()) {
    const auto offsets = py::cast<std::vector<std::int64_t>>(slice_offsets);
    const auto n = static_cast<std::int64_t>(array.shape(0));
    for (std::size_t s = 0; s < offsets.size(); ++s) {
      const bool ascending = s == 0 ? offsets[s] == 0 : offsets[s] >= offsets[s - 1];
      if (!ascending || offsets[s] > n || (s + 1 == offsets.size() && offsets[s] != n)) {
        throw py::value_error(source + ": slice offsets must ascend from 0 to the point count " + std::to_string(n));
      }
    }
  }
  if (slice_offsets.is_none()) {
    if (array.dtype().is(py::dtype::of<float>())) add_points<float>(builder, array, source);
    else add_points<double>(builder, array, source);
  } else {
    // Slice by slice, so the builder marks each start (offsets checked above).
    const auto offsets = py::cast<std::vector<std::int64_t>>(slice_offsets);
    for (std::size_t s = 0; s + 1 < offsets.size(); ++s) {
      builder.begin_slice();
      const py::array part = array.attr("__getitem__")(
          py::slice(static_cast<py::ssize_t>(offsets[s]), static_cast<py::ssize_t>(offsets[s + 1]), 1));
      if (array.dtype().is(py::dtype::of<float>())) add_points<float>(builder, part, source);
      else add_points<double>(builder, part, source);
    }
  }
  Scan scan = builder.finish(false);
  scan.name = name;
  scan.source_path = source;
  return scan;
}

Pose pose_from_array(const py::handle& object, LengthUnit unit, const std::string& what) {
  const auto array = py::array_t<double, py::array::forcecast>::ensure(object);
  if (!array || array.ndim() != 2 || array.shape(0) != 4 || array.shape(1) != 4) {
    throw py::value_error(what + ": expected a 4x4 pose matrix");
  }
  const auto view = array.unchecked<2>();
  Pose pose;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) {
      if (!std::isfinite(view(r, c))) throw py::value_error(what + ": the pose holds a non-finite value");
      pose(r, c) = view(r, c);
    }
  }
  const double cm = centimetres_per(unit);
  pose.block<3, 1>(0, 3) *= cm;
  return pose;
}

py::array_t<double> pose_to_array(const Pose& pose_cm, LengthUnit unit) {
  py::array_t<double> out({4, 4});
  auto view = out.mutable_unchecked<2>();
  const double per_cm = 1.0 / centimetres_per(unit);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) view(r, c) = (c == 3 && r < 3) ? pose_cm(r, c) * per_cm : pose_cm(r, c);
  }
  return out;
}

py::array_t<double> poses_to_array(const std::vector<Pose>& poses_cm, LengthUnit unit) {
  py::array_t<double> out({static_cast<py::ssize_t>(poses_cm.size()), py::ssize_t{4}, py::ssize_t{4}});
  auto view = out.mutable_unchecked<3>();
  const double per_cm = 1.0 / centimetres_per(unit);
  for (std::size_t i = 0; i < poses_cm.size(); ++i) {
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) {
        view(i, r, c) = (c == 3 && r < 3) ? poses_cm[i](r, c) * per_cm : poses_cm[i](r, c);
      }
    }
  }
  return out;
}

/// A scan's points in its file frame (local origin added back), in `unit`, as float64.
py::array_t<double> file_points(const Scan& scan, LengthUnit unit) {
  py::array_t<double> out({static_cast<py::ssize_t>(scan.size()), py::ssize_t{3}});
  auto view = out.mutable_unchecked<2>();
  const double per_cm = 1.0 / centimetres_per(unit);
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const Eigen::Vector3d p = scan.file_point(i) * per_cm;
    for (int k = 0; k < 3; ++k) view(i, k) = p[k];
  }
  return out;
}

py::dict survey_to_dict(const io::Survey& survey) {
  py::dict d;
  d["format"] = survey.format;
  d["unit"] = std::string(to_string(survey.unit));
  const double per_cm = 1.0 / centimetres_per(survey.unit);
  d["origin"] = py::make_tuple(survey.origin_cm.x() * per_cm, survey.origin_cm.y() * per_cm, survey.origin_cm.z() * per_cm);
  d["warnings"] = survey.warnings;
  py::list scans;
  std::vector<Pose> poses;
  for (const Scan& scan : survey.scans) {
    py::dict s;
    s["name"] = scan.name;
    s["source"] = scan.source_path;
    s["points"] = file_points(scan, survey.unit);
    s["pose"] = pose_to_array(scan.pose_cm, survey.unit);
    s["slice_offsets"] = scan.has_slices() ? py::cast(scan.slice_offsets) : py::object(py::none());
    scans.append(s);
  }
  d["scans"] = scans;
  d["truth"] = survey.truth_cm ? py::object(poses_to_array(*survey.truth_cm, survey.unit)) : py::object(py::none());
  return d;
}

// ---- results --------------------------------------------------------------------------------------

py::dict icp_to_dict(const IcpResult& result, LengthUnit unit) {
  py::dict d;
  d["iterations"] = result.iterations();
  d["pairs"] = result.pairs;
  d["rms"] = result.rms_cm / centimetres_per(unit);
  d["stop_reason"] = std::string(to_string(result.stop));
  d["converged"] = result.converged();
  return d;
}

/// map_survey's result: per-scan poses and the report's fields (report.json as a dict).
py::dict run_to_dict(const cli::MapCommand& command, const cli::MapRun& run, const std::string& report_json,
                     bool with_map) {
  const MappingResult& result = run.result;
  const LengthUnit unit = run.survey.unit;
  py::dict d;
  std::vector<Pose> poses, initial;
  py::list names, registered, doubts;
  for (const ScanOutcome& s : result.scans) {
    poses.push_back(s.pose_cm);
    initial.push_back(s.initial_pose_cm);
    names.append(s.name);
    registered.append(s.registered);
    doubts.append(s.health.doubtful() ? s.health.doubt : std::string());
  }
  d["names"] = names;
  d["poses"] = poses_to_array(poses, unit);
  d["initial_poses"] = poses_to_array(initial, unit);
  d["registered"] = registered;
  d["doubts"] = doubts;
  d["interrupted"] = result.interrupted;
  d["format"] = run.survey.format;
  d["unit"] = std::string(to_string(unit));
  const double per_cm = 1.0 / centimetres_per(unit);
  // The poses' origin: a map tied to control is in the grid, less its origin (slam/control_tie.hpp).
  const Eigen::Vector3d origin = result.control ? result.control->origin_cm : run.survey.origin_cm;
  d["origin"] = py::make_tuple(origin.x() * per_cm, origin.y() * per_cm, origin.z() * per_cm);
  // The grid's EPSG code, when the map is tied to control and its file names one (map.laz's CRS).
  d["epsg"] = result.control && result.control->epsg ? py::object(py::int_(*result.control->epsg)) : py::object(py::none());
  d["sources"] = [&] {
    py::list sources;
    for (std::size_t i = 0; i < result.scans.size(); ++i) sources.append(run.survey.scans[i].source_path);
    return sources;
  }();
  d["report"] = py::module_::import("json").attr("loads")(report_json);
  d["settings_preset"] = std::string(to_string(command.options.preset));
  // The survey's frame, as its reader says (io::Survey::frame_3dtk): map.laz converts 3DTK's frame
  // back to right-handed z up, as the views draw it.
  d["frame"] = std::string(run.survey.frame_3dtk ? "3dtk" : "z_up");
  if (with_map) {
    // The merged map as map.ply holds it (world frame = the survey's local frame), in double, with
    // each point's scan index.
    std::size_t total = 0;
    for (const ScanOutcome& s : result.scans) total += s.used_points_cm ? s.used_points_cm->size() : 0;
    py::array_t<double> points({static_cast<py::ssize_t>(total), py::ssize_t{3}});
    py::array_t<std::uint32_t> scan_index(static_cast<py::ssize_t>(total));
    auto p = points.mutable_unchecked<2>();
    auto k = scan_index.mutable_unchecked<1>();
    py::ssize_t row = 0;
    for (std::size_t i = 0; i < result.scans.size(); ++i) {
      const ScanOutcome& s = result.scans[i];
      const Eigen::Matrix3d r = s.world_from_points.block<3, 3>(0, 0);
      const Eigen::Vector3d t = s.world_from_points.block<3, 1>(0, 3);
      if (!s.used_points_cm) continue;
      for (const auto& q : *s.used_points_cm) {
        const Eigen::Vector3d w = (r * q.cast<double>() + t) * per_cm;
        p(row, 0) = w.x(), p(row, 1) = w.y(), p(row, 2) = w.z();
        k(row++) = static_cast<std::uint32_t>(i);
      }
    }
    d["map_points"] = points;
    d["map_scan_index"] = scan_index;
  }
  return d;
}

// ---- hooks the package hands in -------------------------------------------------------------------

/// An InputError from a Python reader's message "PATH: problem" (formats.SurveyFormatError).
[[noreturn]] void throw_input_error(const std::string& message, const std::string& fallback_path) {
  const auto colon = message.find(": ");
  if (colon != std::string::npos && colon > 0) {
    throw InputError(FileLocation{message.substr(0, colon)}, message.substr(colon + 2));
  }
  throw InputError(FileLocation{fallback_path}, message);
}

std::optional<py::function>& python_reader() {
  static std::optional<py::function> reader;
  return reader;
}
std::optional<py::function>& python_extra_outputs() {
  static std::optional<py::function> writer;
  return writer;
}

io::Survey survey_from_dict(const py::dict& d, const std::string& path) {
  io::Survey survey;
  survey.format = py::cast<std::string>(d["format"]);
  survey.unit = parse_length_unit(py::cast<std::string>(d["unit"]));
  const auto origin = py::cast<std::vector<double>>(d["origin"]);
  if (origin.size() != 3) throw py::value_error(path + ": the reader's origin is not 3 values");
  const double cm = centimetres_per(survey.unit);
  survey.origin_cm = Eigen::Vector3d(origin[0], origin[1], origin[2]) * cm;
  for (const py::handle item : py::cast<py::list>(d["scans"])) {
    const py::dict s = py::cast<py::dict>(item);
    const std::string source = py::cast<std::string>(s["source"]);
    Scan scan = scan_from_array(s["points"], py::cast<std::string>(s["name"]), source, survey.unit,
                                s.contains("slice_offsets") ? py::object(s["slice_offsets"]) : py::object(py::none()));
    scan.pose_cm = pose_from_array(s["pose"], survey.unit, source);
    survey.scans.push_back(std::move(scan));
  }
  if (d.contains("warnings")) survey.warnings = py::cast<std::vector<std::string>>(d["warnings"]);
  return survey;
}

/// read_survey's reader for LAS/LAZ and E57: the package's formats.read_foreign_survey. Called
/// from C++ with the GIL released; takes it for the call.
io::Survey read_with_python(const std::filesystem::path& path, const io::SurveyReadSettings& settings) {
  py::gil_scoped_acquire gil;
  if (!python_reader()) throw InputError(FileLocation{path.string()}, "no reader for LAS/LAZ and E57");
  try {
    const py::object unit = settings.read.unit ? py::cast(std::string(to_string(*settings.read.unit))) : py::none();
    const py::dict d = (*python_reader())(path.string(), unit);
    return survey_from_dict(d, path.string());
  } catch (py::error_already_set& e) {
    if (e.matches(PyExc_ValueError) || e.matches(PyExc_OSError)) {
      throw_input_error(py::str(e.value()), path.string());
    }
    throw;
  }
}

cli::ExtraOutputs extra_outputs_with_python() {
  return [](const std::filesystem::path& out_dir, const cli::MapCommand& command, const cli::MapRun& run) {
    py::gil_scoped_acquire gil;
    if (!python_extra_outputs()) return;
    try {
      (*python_extra_outputs())(out_dir.string(), run_to_dict(command, run, "{}", true));
    } catch (py::error_already_set& e) {
      throw OutputError(out_dir.string() + ": " + std::string(py::str(e.value())));
    }
  };
}

// ---- exports: the C++ stream of placed scans, written by the package's LAS/LAZ, COPC and E57 writers --

std::optional<py::function>& python_export_writer() {
  static std::optional<py::function> writer;
  return writer;
}

/// One exported scan as arrays: points (N, 3) float64 in the export's frame and unit, and each
/// attribute the scan carries (intensity float32, rgb uint32 0xRRGGBB, time float64, ring uint16,
/// return_number uint8).
py::dict exported_scan_dict(ExportedScan scan) {
  py::dict d;
  d["index"] = scan.index;
  d["name"] = scan.name;
  d["source"] = scan.source;
  py::array_t<double> points({static_cast<py::ssize_t>(scan.points.size()), py::ssize_t{3}});
  std::memcpy(points.mutable_data(), scan.points.data(), scan.points.size() * sizeof(Eigen::Vector3d));
  d["points"] = points;
  const auto column = [&](const char* name, const auto& values) {
    if (values.empty()) return;
    using T = typename std::decay_t<decltype(values)>::value_type;
    py::array_t<T> array(static_cast<py::ssize_t>(values.size()));
    std::memcpy(array.mutable_data(), values.data(), values.size() * sizeof(T));
    d[name] = array;
  };
  column("intensity", scan.attributes.intensity);
  column("rgb", scan.attributes.rgb);
  column("time", scan.attributes.time_s);
  column("ring", scan.attributes.ring);
  column("return_number", scan.attributes.return_number);
  return d;
}

ExportSummary summary_of(const py::dict& d) {
  ExportSummary summary;
  summary.scans = py::cast<std::size_t>(d["scans"]);
  summary.points = py::cast<std::uint64_t>(d["points"]);
  summary.attributes = py::cast<std::uint8_t>(d["attributes"]);
  summary.completed = py::cast<bool>(d["completed"]);
  if (d.contains("warnings")) summary.warnings = py::cast<std::vector<std::string>>(d["warnings"]);
  return summary;
}

/// Hooks::export_writer: the package's minemap.export.write (GIL taken for the call; the stream
/// releases it while it reads a scan).
cli::ExportWriter export_writer_with_python() {
  return [](SurveyExport& scans, const std::filesystem::path& path, const std::function<bool()>& stop) {
    py::gil_scoped_acquire gil;
    if (!python_export_writer()) throw OutputError(path.string() + ": the package's export writer is not loaded");
    try {
      const py::object result = (*python_export_writer())(py::cast(&scans, py::return_value_policy::reference),
                                                          path.string(), py::cpp_function(stop));
      return summary_of(py::cast<py::dict>(result));
    } catch (py::error_already_set& e) {
      if (e.matches(py::module_::import("minemap._core").attr("InputError"))) throw_input_error(py::str(e.value()), path.string());
      throw OutputError(path.string() + ": " + std::string(py::str(e.value())));
    }
  };
}

// ---- the API ------------------------------------------------------------------------------------

cli::MapCommand parse(const std::vector<std::string>& args) {
  return cli::parse_map_options(args);  // std::invalid_argument -> ValueError
}

/// Ctrl-C between scans: Python's SIGINT handler only sets a flag; this runs it (with the GIL) and
/// reports a KeyboardInterrupt as a stop request.
struct PythonInterrupt {
  bool raised = false;
  bool operator()() {
    py::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() != 0) {
      PyErr_Clear();
      raised = true;
    }
    return raised;
  }
};

py::dict map_survey_api(const py::object& survey_path, const py::object& scans, const py::object& poses,
                        const py::object& names, const std::string& unit_text, const std::vector<std::string>& args,
                        const py::object& out) {
  cli::MapCommand command = parse(args);
  if (!out.is_none()) command.options.out = py::cast<std::string>(out);
  command.command_line = {"minemap.map_survey", survey_path.is_none() ? std::string("<arrays>") : py::cast<std::string>(survey_path)};
  command.command_line.insert(command.command_line.end(), args.begin(), args.end());
  std::optional<io::Survey> given;
  if (survey_path.is_none()) {
    // Scans given as arrays: one survey, in the order given, in `unit`.
    io::Survey survey;
    survey.format = "arrays";
    survey.unit = parse_length_unit(unit_text);
    const auto list = py::cast<py::sequence>(scans);
    const py::ssize_t n = py::len(list);
    if (n == 0) throw py::value_error("scans: an empty list");
    for (py::ssize_t i = 0; i < n; ++i) {
      const std::string name = names.is_none() ? "scan" + std::to_string(i) : py::cast<std::string>(names[py::int_(i)]);
      Scan scan = scan_from_array(list[i], name, "scans[" + std::to_string(i) + "]", survey.unit);
      if (!poses.is_none()) scan.pose_cm = pose_from_array(poses[py::int_(i)], survey.unit, "poses[" + std::to_string(i) + "]");
      survey.scans.push_back(std::move(scan));
    }
    given = std::move(survey);
    command.options.survey = "arrays";
  } else {
    command.options.survey = py::cast<std::string>(survey_path);
  }
  PythonInterrupt interrupt;
  cli::MapRun run;
  std::string report;
  {
    py::gil_scoped_release no_gil;
    run = given ? cli::map_read_survey(command, std::move(*given), 0.0, {}, std::ref(interrupt))
                : cli::run_map_command(command, {}, std::ref(interrupt));
    if (!command.options.out.empty()) {
      report = cli::write_outputs(command, run, extra_outputs_with_python());
    } else {
      report = map_report(run.result, run.truth, command.settings, cli::output_settings(command, run));
    }
  }
  if (interrupt.raised) {
    PyErr_SetNone(PyExc_KeyboardInterrupt);
    throw py::error_already_set();
  }
  return run_to_dict(command, run, report, false);
}

py::dict register_api(const py::handle& source, const py::handle& target, const py::object& init,
                      const std::string& unit_text, const std::vector<std::string>& args) {
  const cli::MapCommand command = parse(args);
  const MappingSettings& settings = command.settings;
  const LengthUnit unit = parse_length_unit(unit_text);
  const Scan data = scan_from_array(source, "source", "source", unit);
  const Scan model = scan_from_array(target, "target", "target", unit);
  const Pose init_cm = init.is_none() ? Pose::Identity() : pose_from_array(init, unit, "init");
  detail::ScanMatch match;
  {
    py::gil_scoped_release no_gil;
    BackendChoice backend = cli::make_backend_for(command.options);
    match = cli::with_threads(command.options, [&] {
      // The pair as `minemap map` registers a scan against the scan before it: both reduced as
      // map reduces them (the settings' reduction: voxel means by default, the model denser), ICP,
      // judged at its end (registration/health.hpp) and, when doubtful, tried again from the same
      // start at wider bounds, coarse to fine (the same code: scan_registration.hpp). On raw dense
      // points ICP can settle short of a pose that the reduced clouds reach (the fast_gicp pair:
      // at the identity's minimum, 50 cm off), and nothing at that minimum looks wrong.
      detail::RunControl control;
      detail::ScanPreparation preparation(settings, *backend.backend);
      const detail::PreparedScan prepared = preparation.prepare(data, control);
      const detail::PreparedScan reference = preparation.prepare(model, control);
      const std::vector<WorldModel> models = {{reference.model_cloud.get(), model.world_from_points()}};
      Scan placed = data;
      placed.pose_cm = init_cm;
      const detail::ScanRegistration registration(settings, *backend.backend);
      return registration.register_scan(prepared, placed.world_from_points(),
                                        [&](float, const Pose&) { return models; });
    });
  }
  const IcpResult& kept = match.kept();
  // T_world_points of the data back to T_world_source (the local origin taken out).
  Scan placed = data;
  placed.set_world_from_points(kept.world_from_data);
  py::dict d = icp_to_dict(kept, unit);
  d["pose"] = pose_to_array(kept.ok() ? placed.pose_cm : init_cm, unit);
  const RegistrationHealth& h = match.health;
  const double per_cm = 1.0 / centimetres_per(unit);
  d["judged"] = h.judged;
  d["trusted"] = kept.ok() && !h.doubtful();
  d["doubt"] = h.doubt;
  d["retry_bound"] = double(h.retry_bound_cm) * per_cm;
  py::dict health;
  health["paired_fraction"] = h.paired_fraction;
  health["beyond_bound_fraction"] = h.beyond_bound_fraction;
  health["edge_fraction"] = h.edge_fraction;
  health["rms"] = h.rms_cm * per_cm;
  health["moved"] = h.moved_cm * per_cm;
  health["pair_bound"] = double(h.pair_bound_cm) * per_cm;
  health["translation_constraint"] = h.translation_constraint;
  health["rotation_constraint"] = h.rotation_constraint;
  d["health"] = health;
  return d;
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  m.doc() = "minemap's C++ core (see the package minemap)";
  py::register_exception<InputError>(m, "InputError", PyExc_ValueError);
  py::register_exception<BackendError>(m, "BackendError", PyExc_RuntimeError);
  py::register_exception<OutputError>(m, "OutputError", PyExc_OSError);

  m.def("run_cli", [](const std::vector<std::string>& args) {
    py::gil_scoped_release no_gil;
    cli::Hooks hooks;
    hooks.extra_outputs = extra_outputs_with_python();
    hooks.extra_output_names = {"map.laz"};
    hooks.export_writer = export_writer_with_python();
    return cli::run(args, hooks);
  }, py::arg("args"), "Runs the command line (arguments without the program name); returns the exit code.");

  m.def("map_options", [](const std::string& preset) {
    py::list list;
    for (const auto& o : cli::map_options(parse_preset(preset))) {
      list.append(py::make_tuple(o.name, o.default_value, o.help, o.flag));
    }
    return list;
  }, py::arg("preset") = "default", "`minemap map`'s options: (name, default, help, is_flag).");

  // The program's exit codes by name (cli/exit_codes.hpp), for the package's batch runner.
  py::dict exit_codes;
  for (const auto& [code, name] : kExitCodeNames) exit_codes[name] = static_cast<int>(code);
  m.attr("exit_codes") = exit_codes;
  m.attr("__version__") = cli::version();

  m.def("check_map_options", [](const std::vector<std::string>& args) { parse(args); }, py::arg("args"));

  m.def("set_foreign_survey_reader", [](py::object reader) {
    if (reader.is_none()) {
      python_reader().reset();
      io::set_foreign_survey_reader({});
    } else {
      python_reader() = py::cast<py::function>(reader);
      io::set_foreign_survey_reader(read_with_python);
    }
  }, py::arg("reader"));
  py::class_<SurveyExport>(m, "SurveyExport",
                           "The registered survey, scan by scan, as `minemap export` streams it (report/survey_export.hpp).")
      .def(py::init([](const std::string& out, const std::string& frame, double voxel_cm,
                       const std::vector<std::string>& scans) {
             ExportSettings settings;
             if (frame != "z-up" && frame != "survey") throw py::value_error("frame: 'z-up' or 'survey', not '" + frame + "'");
             settings.frame = frame == "survey" ? ExportSettings::Frame::kSurvey : ExportSettings::Frame::kZUp;
             settings.voxel_cm = voxel_cm;
             settings.scans = scans;
             return std::make_unique<SurveyExport>(out, settings);
           }),
           py::arg("out"), py::arg("frame") = "z-up", py::arg("voxel_cm") = 0.0,
           py::arg("scans") = std::vector<std::string>{})
      .def("next", [](SurveyExport& self) -> py::object {
             std::optional<ExportedScan> scan;
             {
               py::gil_scoped_release no_gil;
               scan = self.next();
             }
             if (!scan) return py::none();
             return exported_scan_dict(std::move(*scan));
           }, "The next scan as arrays (a dict), or None after the last.")
      .def("attributes", &SurveyExport::attributes, "The first scan's attributes (a PointAttribute mask).")
      .def_property_readonly("scans", &SurveyExport::scans)
      .def_property_readonly("points_expected", &SurveyExport::points_expected)
      .def_property_readonly("frame_description", &SurveyExport::frame_description)
      .def_property_readonly("unit", [](const SurveyExport& self) { return std::string(to_string(self.unit())); })
      .def_property_readonly("origin", [](const SurveyExport& self) {
        const Eigen::Vector3d o = self.origin();
        return py::make_tuple(o.x(), o.y(), o.z());
      })
      .def_property_readonly("survey", &SurveyExport::survey)
      .def_property_readonly("epsg", [](const SurveyExport& self) -> py::object {
        if (const auto code = self.epsg()) return py::int_(*code);
        return py::none();
      })
      .def_property_readonly("skipped", &SurveyExport::skipped);
  m.attr("attribute_bits") = py::dict(py::arg("intensity") = int(kIntensity), py::arg("colour") = int(kColour),
                                      py::arg("time") = int(kTime), py::arg("ring") = int(kRing),
                                      py::arg("return_number") = int(kReturnNumber));
  m.def("describe_attributes", &describe_attributes, py::arg("mask"));
  m.def("write_export_ply", [](SurveyExport& scans, const std::string& path) {
    ExportSummary summary;
    {
      py::gil_scoped_release no_gil;
      summary = write_export_ply(scans, path);
    }
    py::dict d;
    d["scans"] = summary.scans;
    d["points"] = summary.points;
    d["attributes"] = summary.attributes;
    d["completed"] = summary.completed;
    d["warnings"] = summary.warnings;
    return d;
  }, py::arg("scans"), py::arg("path"));
  m.def("set_export_writer", [](py::object writer) {
    if (writer.is_none()) python_export_writer().reset();
    else python_export_writer() = py::cast<py::function>(writer);
  }, py::arg("writer"));

  m.def("set_extra_outputs", [](py::object writer) {
    if (writer.is_none()) python_extra_outputs().reset();
    else python_extra_outputs() = py::cast<py::function>(writer);
  }, py::arg("writer"));
  // The hooks hold Python objects: drop them before the interpreter goes.
  py::module_::import("atexit").attr("register")(py::cpp_function([] {
    io::set_foreign_survey_reader({});
    python_reader().reset();
    python_extra_outputs().reset();
    python_export_writer().reset();
  }));

  m.def("read_survey", [](const std::string& path, const std::vector<std::string>& args) {
    const cli::MapCommand command = parse(args);
    io::Survey survey;
    {
      py::gil_scoped_release no_gil;
      survey = io::read_survey(path, cli::survey_read_settings(command.options, command.settings));
    }
    return survey_to_dict(survey);
  }, py::arg("path"), py::arg("args"));

  m.def("map_survey", &map_survey_api, py::arg("survey"), py::arg("scans"), py::arg("poses"), py::arg("names"),
        py::arg("unit"), py::arg("args"), py::arg("out"));
  m.def("register", &register_api, py::arg("source"), py::arg("target"), py::arg("init"), py::arg("unit"),
        py::arg("args"));
}
