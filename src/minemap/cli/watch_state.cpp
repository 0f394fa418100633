#include "minemap/cli/watch_state.hpp"

#include <nlohmann/json.hpp>

#include "minemap/core/error.hpp"
#include "minemap/io/text_reader.hpp"

namespace minemap::cli {
namespace {

using json = nlohmann::json;
constexpr const char* kFormat = "minemap watch state";
constexpr int kVersion = 1;

json matrix_json(const Pose& pose) { return std::vector<double>(pose.data(), pose.data() + 16); }  // column-major
Pose matrix_of(const json& j) {
  const auto values = j.get<std::vector<double>>();
  if (values.size() != 16) throw std::invalid_argument("a pose is not 16 numbers");
  Pose pose;
  std::copy(values.begin(), values.end(), pose.data());
  return pose;
}

json icp_json(const IcpResult& r) {
  return {{"world_from_data", matrix_json(r.world_from_data)}, {"approximate_iterations", r.approximate_iterations},
          {"exact_iterations", r.exact_iterations}, {"refine_iterations", r.refine_iterations},
          {"accelerations", r.accelerations}, {"rejected_accelerations", r.rejected_accelerations},
          {"pairs", r.pairs}, {"rms_cm", r.rms_cm}, {"stop", static_cast<int>(r.stop)}};
}
IcpResult icp_of(const json& j) {
  IcpResult r;
  r.world_from_data = matrix_of(j.at("world_from_data"));
  r.approximate_iterations = j.at("approximate_iterations");
  r.exact_iterations = j.at("exact_iterations");
  r.refine_iterations = j.at("refine_iterations");
  r.accelerations = j.at("accelerations");
  r.rejected_accelerations = j.at("rejected_accelerations");
  r.pairs = j.at("pairs");
  r.rms_cm = j.at("rms_cm");
  const int stop = j.at("stop");
  if (stop < 0 || stop > static_cast<int>(IcpStop::kNumericFailure)) throw std::invalid_argument("unknown ICP stop");
  r.stop = static_cast<IcpStop>(stop);
  return r;
}

json health_json(const RegistrationHealth& h) {
  return {{"judged", h.judged}, {"data_points", h.data_points}, {"paired_fraction", h.paired_fraction},
          {"beyond_bound_fraction", h.beyond_bound_fraction}, {"edge_fraction", h.edge_fraction},
          {"rms_cm", h.rms_cm}, {"correction_cm", h.correction_cm}, {"correction_deg", h.correction_deg},
          {"moved_cm", h.moved_cm}, {"translation_constraint", h.translation_constraint},
          {"weakest_direction", {h.weakest_direction.x(), h.weakest_direction.y(), h.weakest_direction.z()}},
          {"rotation_constraint", h.rotation_constraint},
          {"weakest_axis", {h.weakest_axis.x(), h.weakest_axis.y(), h.weakest_axis.z()}},
          {"failed", static_cast<int>(h.failed)},
          {"pair_bound_cm", h.pair_bound_cm}, {"retry_bound_cm", h.retry_bound_cm}, {"doubt", h.doubt},
          {"out_of_reach", h.out_of_reach}, {"after_loop_closure", h.after_loop_closure}};
}
RegistrationHealth health_of(const json& j) {
  RegistrationHealth h;
  h.judged = j.at("judged");
  h.data_points = j.at("data_points");
  h.paired_fraction = j.at("paired_fraction");
  h.beyond_bound_fraction = j.at("beyond_bound_fraction");
  h.edge_fraction = j.at("edge_fraction");
  h.rms_cm = j.at("rms_cm");
  h.correction_cm = j.at("correction_cm");
  h.correction_deg = j.at("correction_deg");
  h.moved_cm = j.at("moved_cm");
  h.translation_constraint = j.at("translation_constraint");
  const auto w = j.at("weakest_direction").get<std::vector<double>>();
  if (w.size() != 3) throw std::invalid_argument("weakest_direction is not 3 numbers");
  h.weakest_direction = Eigen::Vector3d(w[0], w[1], w[2]);
  // Written since the rotation constraint (a watch saved before reads as not measured).
  h.rotation_constraint = j.value("rotation_constraint", -1.0);
  const auto a = j.value("weakest_axis", std::vector<double>{0.0, 0.0, 0.0});
  if (a.size() != 3) throw std::invalid_argument("weakest_axis is not 3 numbers");
  h.weakest_axis = Eigen::Vector3d(a[0], a[1], a[2]);
  const int failed = j.value("failed", 0);
  if (failed < 0 || failed > static_cast<int>(HealthTest::kUnpinnedTurn)) {
    throw std::invalid_argument("unknown health test");
  }
  h.failed = static_cast<HealthTest>(failed);
  h.pair_bound_cm = j.at("pair_bound_cm");
  h.retry_bound_cm = j.at("retry_bound_cm");
  h.doubt = j.at("doubt");
  h.out_of_reach = j.at("out_of_reach");
  h.after_loop_closure = j.at("after_loop_closure");
  return h;
}

json outcome_json(const ScanOutcome& s) {
  json frames = json::array();
  for (const auto& f : s.frames) frames.push_back({{"pose_cm", matrix_json(f.pose_cm)}, {"type", f.type}});
  return {{"name", s.name}, {"pose_cm", matrix_json(s.pose_cm)}, {"initial_pose_cm", matrix_json(s.initial_pose_cm)},
          {"world_from_points", matrix_json(s.world_from_points)}, {"frames", frames},
          {"last_match", icp_json(s.last_match)}, {"health", health_json(s.health)},
          {"relaxation_matches", s.relaxation_matches}, {"match_s", s.match_s}, {"registered", s.registered},
          {"failure", s.failure}};
}
ScanOutcome outcome_of(const json& j) {
  ScanOutcome s;
  s.name = j.at("name");
  s.pose_cm = matrix_of(j.at("pose_cm"));
  s.initial_pose_cm = matrix_of(j.at("initial_pose_cm"));
  s.world_from_points = matrix_of(j.at("world_from_points"));
  for (const auto& f : j.at("frames")) s.frames.push_back({matrix_of(f.at("pose_cm")), f.at("type").get<int>()});
  s.last_match = icp_of(j.at("last_match"));
  s.health = health_of(j.at("health"));
  s.relaxation_matches = j.at("relaxation_matches");
  s.match_s = j.at("match_s");
  s.registered = j.at("registered");
  s.failure = j.at("failure");
  return s;
}

}  // namespace

std::string watch_state_json(const WatchState& state) {
  const MappingResult& r = state.result;
  json scans = json::array();
  for (std::size_t i = 0; i < r.scans.size(); ++i) {
    json scan = outcome_json(r.scans[i]);
    scan["source"] = i < state.sources.size() ? state.sources[i] : std::string();
    scans.push_back(std::move(scan));
  }
  const json j = {{"format", kFormat},
                  {"version", kVersion},
                  {"options", state.options},
                  {"finished", state.finished},
                  {"scans", scans},
                  {"queue", state.queue},
                  {"step1_icp_iterations", r.step1_icp_iterations},
                  {"step3_icp_iterations", r.step3_icp_iterations},
                  {"relaxation_matches", r.relaxation_matches},
                  {"notes", r.notes},
                  {"times_s",
                   {{"filter", r.times.filter_s},
                    {"tree_build", r.times.tree_build_s},
                    {"pairwise", r.times.pairwise_s},
                    {"relaxation", r.times.relaxation_s}}}};
  return j.dump(1) + "\n";
}

WatchState read_watch_state(const std::filesystem::path& path) {
  const std::string text = io::detail::read_file_bytes(path);
  try {
    const json j = json::parse(text);
    if (j.at("format") != kFormat || j.at("version") != kVersion) {
      throw std::invalid_argument("not a minemap watch state of version " + std::to_string(kVersion));
    }
    WatchState state;
    state.options = j.at("options");
    state.finished = j.at("finished");
    for (const auto& scan : j.at("scans")) {
      state.result.scans.push_back(outcome_of(scan));
      state.sources.push_back(scan.at("source"));
    }
    state.queue = j.at("queue").get<std::vector<std::size_t>>();
    state.result.step1_icp_iterations = j.at("step1_icp_iterations");
    state.result.step3_icp_iterations = j.at("step3_icp_iterations");
    state.result.relaxation_matches = j.at("relaxation_matches");
    state.result.notes = j.at("notes").get<std::vector<std::string>>();
    const json& times = j.at("times_s");
    state.result.times.filter_s = times.at("filter");
    state.result.times.tree_build_s = times.at("tree_build");
    state.result.times.pairwise_s = times.at("pairwise");
    state.result.times.relaxation_s = times.at("relaxation");
    return state;
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(FileLocation{path.string()}, std::string("not a watch state minemap can resume: ") + e.what());
  }
}

}  // namespace minemap::cli
