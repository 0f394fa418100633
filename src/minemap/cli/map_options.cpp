// `map`'s options (map_options.hpp). One declaration per option, in the group of its stage; its
// default is the bound field's value, and every number in a help text is printed from the settings.
#include "minemap/cli/map_options.hpp"

#include <algorithm>
#include <charconv>
#include <sstream>
#include <type_traits>

namespace minemap::cli {
namespace {

/// The shortest text that reads back as `value` (0.3f is "0.3", not 0.30000001192092896).
template <typename T>
std::string number_text(T value) {
  char text[64];
  const auto end = std::to_chars(text, text + sizeof text, value).ptr;
  return std::string(text, end);
}

std::string key_of(const std::string& name) {
  std::string key = name.substr(name.find_first_not_of('-'));
  std::replace(key.begin(), key.end(), '-', '_');
  return key;
}

/// 3 -> "3rd".
std::string ordinal(int n) {
  const int last = n % 10, tens = n % 100;
  const char* suffix = (tens >= 11 && tens <= 13) ? "th" : last == 1 ? "st" : last == 2 ? "nd" : last == 3 ? "rd" : "th";
  return std::to_string(n) + suffix;
}

/// {4, 16} -> "4x and 16x".
std::string multiples(const std::vector<float>& factors) {
  std::string text;
  for (std::size_t i = 0; i < factors.size(); ++i) {
    text += (i == 0 ? "" : i + 1 == factors.size() ? " and " : ", ") + number_text(factors[i]) + "x";
  }
  return text.empty() ? "no wider bound" : text;
}

}  // namespace

bool changes_no_pose(const std::string& group) { return group == groups::kRun || group == groups::kWatch; }

template <typename T>
CLI::Option* MapOptionTable::number(const char* group, const std::string& name, T& value, const std::string& help) {
  recorders_.push_back([&value, key = key_of(name), changes = !changes_no_pose(group)] {
    return RecordedSetting{key, RecordedSetting::Kind::kNumber, number_text(value), changes};
  });
  return app_.add_option(name, value, help)->capture_default_str()->group(group);
}

CLI::Option* MapOptionTable::numbers(const char* group, const std::string& name, std::vector<float>& value,
                                     const std::string& help) {
  recorders_.push_back([&value, key = key_of(name), changes = !changes_no_pose(group)] {
    std::string list;
    for (std::size_t i = 0; i < value.size(); ++i) list += (i == 0 ? "" : ",") + number_text(value[i]);
    return RecordedSetting{key, RecordedSetting::Kind::kNumbers, list, changes};
  });
  return app_.add_option(name, value, help)->delimiter(',')->capture_default_str()->group(group);
}

CLI::Option* MapOptionTable::flag(const char* group, const std::string& name, bool& value, const std::string& help) {
  recorders_.push_back([&value, key = key_of(name), changes = !changes_no_pose(group)] {
    return RecordedSetting{key, RecordedSetting::Kind::kFlag, value ? "true" : "false", changes};
  });
  return app_.add_flag(name, value, help)->group(group);
}

template <typename Enum, std::size_t N>
CLI::Option* MapOptionTable::choice(const char* group, const std::string& name, Enum& value,
                                    const std::array<EnumName<Enum>, N>& names, Enum (*parse)(const std::string&),
                                    const std::string& help) {
  recorders_.push_back([&value, &names, key = key_of(name), changes = !changes_no_pose(group)] {
    return RecordedSetting{key, RecordedSetting::Kind::kText, name_in(names, value), changes};
  });
  return app_.add_option_function<std::string>(name, [&value, parse](const std::string& text) { value = parse(text); },
                                                help)
      ->check(CLI::IsMember(names_in(names)))
      ->default_str(name_in(names, value))
      ->group(group);
}

template <typename Text>
CLI::Option* MapOptionTable::text(const char* group, const std::string& name, Text& value, const std::string& help) {
  recorders_.push_back([&value, key = key_of(name), changes = !changes_no_pose(group)] {
    std::string text;
    if constexpr (std::is_same_v<Text, fs::path>) text = value.string();
    else text = value;
    return RecordedSetting{key, RecordedSetting::Kind::kText, text, changes};
  });
  return app_.add_option(name, value, help)->group(group);
}

std::vector<RecordedSetting> MapOptionTable::record() const {
  std::vector<RecordedSetting> recorded;
  for (const auto& recorder : recorders_) recorded.push_back(recorder());
  return recorded;
}

MapOptionTable::MapOptionTable(CLI::App& app, MapCommand& target) : app_(app) {
  MapOptions& map = target.options;
  MappingSettings& mapping = target.settings;
  declare_run(map);
  declare_input(map);
  declare_reduction(map, mapping);
  declare_matching(map, mapping);
  declare_relaxation(mapping);
  declare_health(map, mapping);
  declare_loops(map, mapping);
}

void MapOptionTable::declare_run(MapOptions& map) {
  const char* g = groups::kRun;
  number(g, "--threads", map.threads, "Worker threads (0 = all cores)");
  number(g, "--held-clouds-mb", map.held_clouds_mb,
         "CPU: the prepared clouds held in memory at most (MB); the scans used least recently go to a spill file "
         "in the output folder and are read back when needed (0 = hold all)");
  text(g, "--opencl-device", map.opencl_device,
       "OpenCL device: a substring of 'platform / device' (same as MINEMAP_OPENCL_DEVICE)");
  choice(g, "--backend", map.backend, kBackendNames, parse_backend, "Where the search runs");
  flag(g, "--quiet", map.quiet, "Print nothing but errors");
  flag(g, "--accept-doubtful", map.accept_doubtful,
       "Exit 0 even when a match was judged doubtful (still named on stderr and in report.json)");
  flag(g, "--write-unregistered", map.write_unregistered,
       "Write the outputs even when a scan could not be registered (exit code 4 still)");
}

void MapOptionTable::declare_input(MapOptions& map) {
  const char* g = groups::kInput;
  text(g, "--unit", map.unit, "Unit of the survey files: m or cm (default: cm for uos, m otherwise)");
  number(g, "--points-per-slice", map.points_per_slice,
         "uos files without slice markers: points per slice (0: found from the scanner order)");
  flag(g, "--no-slice-detection", map.no_slice_detection,
       "uos files without slice markers: do not look for slices in the order of the points");
  text(g, "--initial-poses", map.initial_poses,
       "Initial poses (TUM, KITTI, 4x4 or graph file; commas allowed), one per scan in the order printed");
  text(g, "--reference-poses", map.reference_poses,
       "Reference poses for the error report, any survey (formats as --initial-poses)");
  flag(g, "--right-handed-to-3dtk", map.right_handed_to_3dtk, "Convert right-handed input to 3DTK's frame");
  text(g, "--control", map.control,
       "Survey control: known points in the mine's grid and the scans that observe them (README, \"Survey "
       "control\"); the map, its outputs and exports are then in the grid, each scan with its sigma");
}

void MapOptionTable::declare_reduction(MapOptions& map, MappingSettings& mapping) {
  const char* g = groups::kReduction;
  SliceFilterSettings& filter = mapping.filter;
  choice(g, "--reduction", mapping.reduction, kReductionNames, parse_reduction,
         "slices (the paper's slice filter) | voxel (the mean of each --voxel-cm cell, every scan)");
  number(g, "--voxel-cm", mapping.voxel_cm, "Voxel size of --reduction voxel");
  number(g, "--model-voxel-cm", mapping.model_voxel_cm, "Voxel size of the models of --reduction voxel (0 = the data)");
  flag(g, "--no-filter", map.no_filter,
       "Skip the slice filter (median + reduction + every " + ordinal(filter.slice_stride) + " slice)");
  flag(g, "--no-median", map.no_median, "Slice filter without its median filter");
  flag(g, "--no-spacing-reduction", map.no_spacing_reduction,
       "Slice filter without its reduction (points " + number_text(filter.min_point_spacing_cm) + " cm apart)");
  number(g, "--median-window", filter.median_window, "Median filter window (points)");
  number(g, "--outlier-threshold-cm", filter.outlier_threshold_cm, "Median filter threshold");
  number(g, "--min-point-spacing-cm", filter.min_point_spacing_cm, "Reduction spacing");
  number(g, "--slice-stride", filter.slice_stride, "Keep every n-th slice");
  number(g, "--model-slice-stride", mapping.model_slice_stride,
         "Scans matched against keep every n-th slice (denser than the data: less bias)");
  flag(g, "--sparse-models", map.sparse_models,
       "Match against clouds reduced like the data, as the paper does (faster, less accurate)");
  number(g, "--point-stride", mapping.unstructured_point_stride, "Scans without slices: keep every n-th point");
  number(g, "--bucket-size", mapping.tree.bucket_size, "kd-tree bucket size");
  choice(g, "--deskew", mapping.motion.deskew, kDeskewModeNames, parse_deskew_mode,
         "auto (a moving sensor's sweeps, whose points carry times, are deskewed by the motion estimated for "
         "them) | off");
  number(g, "--max-sweep-s", mapping.motion.max_sweep_s,
         "Points' times spanning more than this are not one sweep of a moving sensor (not deskewed)");
}

void MapOptionTable::declare_matching(MapOptions& map, MappingSettings& mapping) {
  const char* g = groups::kMatching;
  IcpSettings& icp = mapping.icp;
  choice(g, "--preset", map.preset, kPresetNames, parse_preset,
         "default (whole-survey: voxel means, metascan) | simultaneous (the paper's relaxation, minemap's ICP) | "
         "paper (as published); the options below adjust it");
  choice(g, "--mode", mapping.mode, kMatchingModeNames, parse_matching_mode,
         "How scans are matched (the paper's section IV.B)");
  choice(g, "--search", icp.method, kSearchMethodNames, parse_search_method,
         "kd (exact) | apx (approximate, then exact) | brute");
  number(g, "--max-pair-dist-cm", icp.max_pair_dist_cm, "Maximum point-pair distance");
  number(g, "--refine-fraction", icp.refine_pair_dist_fraction,
         "After converging, refine at this fraction of the pair bound (0 = off)");
  number(g, "--max-iterations", icp.termination.max_iterations, "ICP iteration cap");
  number(g, "--min-step-cm", icp.termination.min_translation_step_cm, "ICP converged: a step moves less than this...");
  number(g, "--min-step-deg", icp.termination.min_rotation_step_deg, "...and turns less than this");
  number(g, "--min-pairs", icp.termination.min_pairs,
         "ICP fails with fewer pairs (at most --min-overlap-pairs is asked for in mapping)");
  flag(g, "--plain-icp", map.plain_icp,
       "ICP as in the paper, without Anderson acceleration (the default accelerates: fewer iterations)");
  number(g, "--acceleration-history", icp.acceleration_history, "Anderson acceleration: ICP steps it extrapolates");
  number(g, "--min-overlap-pairs", mapping.min_overlap_pairs, "Overlap threshold (pairs)");
  number(g, "--min-overlap-fraction", mapping.min_overlap_fraction,
         "...or this fraction of a scan's reduced points, where that is fewer (small scans)");
  choice(g, "--motion-model", mapping.motion.model, kMotionModelNames, parse_motion_model,
         "Where a scan starts: odometry (its pose file's step) | constant-velocity (the previous registered step "
         "again) | auto (constant velocity where the scans carry no poses)");
  number(g, "--adaptive-bound-sigmas", mapping.motion.adaptive_bound_sigmas,
         "Constant velocity: the first match starts at this many RMS prediction errors when wider than the pair "
         "bound (0 = off)");
  number(g, "--slide-constraint", mapping.motion.slide_constraint,
         "Constant velocity: a match pinned along its weakest direction less than this fraction of its best, and "
         "moved along it more than the pair bound, is matched again from the prediction along it; that match is "
         "kept when trusted, nearer the prediction and a clearly closer fit (0 = off)");
  number(g, "--weak-step-constraint", mapping.motion.weak_step_constraint,
         "Timed sweeps: where the last match pinned a direction less than this fraction of its best, the next "
         "start moves along it as the recent well-pinned steps did, not as the last step did (0 = off)");
  number(g, "--sweep-spring-pairs", mapping.motion.sweep_start_spring_pairs,
         "Timed sweeps: a match from the prediction holds the sensor to its start with a spring as strong as this "
         "many point pairs; along what the surfaces hardly pin, the start holds (a narrow field only, "
         "--sweep-spring-max-field-deg; 0 = off)");
  number(g, "--sweep-spring-full-error-cm", mapping.motion.sweep_spring_full_error_cm,
         "Timed sweeps: the spring weighs fully while the recent predictions were off by at most this (RMS), less "
         "with the square of their error beyond");
  number(g, "--sweep-spring-max-field-deg", mapping.motion.sweep_spring_max_field_deg,
         "Timed sweeps: the spring holds only sweeps whose points span less azimuth than this about the sensor (a "
         "narrow field; 360 = every sweep)");
  number(g, "--sprung-release-cm", mapping.motion.sprung_release_cm,
         "Timed sweeps: a held match that ended further than this from its prediction is matched again without the "
         "spring; where the two disagree, the scan's features decide, or the scan is doubtful");
  number(g, "--first-sweep-rematch", mapping.motion.first_sweep_rematch_scans,
         "Timed sweeps: the first sweep is matched again against this many sweeps after it once they are in, and "
         "they move together to where that puts them (0 = off)");
  flag(g, "--no-first-sweep-fit", map.no_first_sweep_fit,
       "Timed sweeps: the first sweep matched again is deskewed by the step into sweep 1, its own motion not "
       "fitted");
  number(g, "--max-unpinned-turn-deg", mapping.motion.max_unpinned_turn_deg,
         "Timed sweeps: doubtful when the matches of the last second turned the sensor more than this about axes "
         "their surfaces hardly pin (a rosette scanner's pattern turns them), and those turns are taken out "
         "(0 = off)");
  number(g, "--metascan-margin-cm", mapping.metascan_margin_cm,
         "Metascan: model points within the scan's box grown by the pair bound and this");
  number(g, "--local-map-cell-cm", mapping.motion.local_map_cell_cm,
         "A moving sensor's scans (timed sweeps, or scans without odometry): the metascan keeps one point per cell of "
         "this size, the nearest scan's (0 = all)");
  number(g, "--local-map-sweeps", mapping.motion.local_map_sweeps,
         "A spinning sensor's timed sweeps: one metascan serves up to this many sweeps in a row, grown by their "
         "expected move (1 = one for every sweep)");
  number(g, "--provisional-step-factor", mapping.motion.provisional_step_factor,
         "A sweep's first match, before its deskew is refined, converges at this many times --min-step-cm/-deg "
         "(1 = as any match)");
  flag(g, "--provisional-all-points", map.provisional_all_points,
       "A sweep's first match, before its deskew is refined, matches all its points (the default matches the "
       "health probe's, every --health-probe-stride-th)");
  number(g, "--wide-coarse-kernel", mapping.motion.wide_coarse_kernel_fraction,
         "Keyframes without times or odometry: once the adaptive bound is learned, the first match's coarse stage "
         "weighs its pairs by a Geman-McClure kernel at this fraction of the bound (0 = off: every pair weighs 1)");
  flag(g, "--moving-point-to-plane", map.moving_point_to_plane,
       "A moving sensor's matches (timed sweeps, or scans without odometry) minimise, after their coarse stage, the "
       "distances to each scan's own planes (point-to-plane) instead of the paper's point-to-point distances");
  flag(g, "--wide-coarse-all-points", map.wide_coarse_all_points,
       "The first match at the adaptive bound runs its coarse stage on all the scan's points (the default: the "
       "health probe's; the fine stage matches all of them)");
  choice(g, "--refine-search", mapping.motion.refine_search, kRefineSearchNames, parse_refine_search,
         "Which timed sweeps' matches after their deskew's refinement, starting where their first match converged, "
         "search exactly from the first iteration, without the paper's approximate phase: papers (none), wide-exact (a "
         "spinning sensor's, not a narrow field's), exact (every sweep's); 0.93-0.96x the time on the simulated drives");
}

void MapOptionTable::declare_relaxation(MappingSettings& mapping) {
  const char* g = groups::kRelaxation;
  number(g, "--moved-translation-cm", mapping.moved_translation_cm,
         "Relaxation: a match that moves a scan more than this re-queues its neighbours");
  number(g, "--moved-rotation-deg", mapping.moved_rotation_deg, "...or turns it more than this");
  number(g, "--max-relaxation-matches", mapping.max_relaxation_matches_per_scan,
         "Relaxation matches after each new scan; the rest wait for the next scan (0 = empty the queue every "
         "time, as the paper)");
  number(g, "--max-relaxation-neighbours", mapping.max_relaxation_neighbours,
         "Relaxation: match a scan against at most this many overlapping scans, nearest first (0 = all, as the "
         "paper)");
  number(g, "--relaxation-min-step-cm", mapping.relaxation_min_step_cm,
         "Relaxation matches converged: a step moves less than this (0 = ICP's own --min-step-cm)...");
  number(g, "--relaxation-min-step-deg", mapping.relaxation_min_step_deg, "...and turns less than this");
}

void MapOptionTable::declare_health(MapOptions& map, MappingSettings& mapping) {
  const char* g = groups::kHealth;
  HealthSettings& health = mapping.health;
  flag(g, "--no-health-check", map.no_health_check, "Do not judge matches (nothing is then called doubtful)");
  number(g, "--health-wide-factor", health.wide_factor, "Judging searches this many pair bounds wide");
  number(g, "--health-probe-stride", health.probe_stride, "Judging uses every n-th point of a scan");
  number(g, "--health-min-paired-fraction", health.min_paired_fraction,
         "Doubtful: fewer of its points paired within the bound");
  number(g, "--health-max-beyond-bound-fraction", health.max_beyond_bound_fraction,
         "Doubtful: more of its counterparts just beyond the bound");
  number(g, "--health-max-edge-fraction", health.max_edge_fraction, "Doubtful: more pairs in the bound's outer half");
  number(g, "--health-max-reach", health.max_reach, "Doubtful: its points moved more pair bounds than this");
  number(g, "--health-min-translation-constraint", health.min_translation_constraint,
         "Doubtful (degenerate): the weakest pinned direction over the strongest below this");
  number(g, "--plane-cell-cm", mapping.plane_cell_cm,
         "Planes (the constraint test, loop edges) are fitted in cubes of this size");
  flag(g, "--no-retry", map.no_retry,
       "Do not try a doubtful match again from " + multiples(mapping.retry_bound_factors) +
           " the pair bound (coarse to fine)");
  numbers(g, "--retry-bound-factors", mapping.retry_bound_factors,
          "A doubtful match is tried again from these multiples of the pair bound (comma-separated)");
  number(g, "--max-retry-bound-cm", mapping.max_retry_bound_cm, "No retry (or loop match) starts wider than this");
  flag(g, "--no-recovery", map.no_recovery,
       "Sequences without odometry: do not register a doubtful or failed scan again without a start (its FPFH "
       "features against the local map's, RANSAC), then match it from there");
  number(g, "--recovery-voxel-cm", mapping.recovery.global.features.voxel_cm,
         "Recovery: features on one point per cube of this size (normals within 2x, features within 5x)");
  number(g, "--recovery-reach-cm", mapping.recovery.reach_cm,
         "Recovery: the local map reaches this far beyond the scan's box at the previous scan's pose");
}

void MapOptionTable::declare_loops(MapOptions& map, MappingSettings& mapping) {
  const char* g = groups::kLoops;
  LoopClosureSettings& loops = mapping.loops;
  flag(g, "--no-loop-closing", map.no_loops,
       "Do not close loops (a scan near one " + std::to_string(loops.min_scan_gap) +
           "+ scans earlier matched against it, then the scan graph relaxed); the metascan then holds every "
           "nearby scan");
  number(g, "--loop-distance-cm", loops.max_distance_cm, "Loop candidates: scans whose positions are this close (cm)");
  number(g, "--loop-min-scan-gap", loops.min_scan_gap, "Loop candidates: at least this many scans apart...");
  number(g, "--loop-min-path-cm", loops.min_path_cm, "...with at least this much drive between them");
  number(g, "--loop-return-max-path-cm", loops.max_return_path_cm,
         "A return to known places longer than this drive gets one loop edge per this much (cm; 0 = one edge a return)");
  numbers(g, "--loop-bound-factors", loops.bound_factors,
          "A loop match tries these multiples of the pair bound, coarse to fine (comma-separated)");
  flag(g, "--loop-edges-alike", map.loop_edges_alike,
       "Every pose graph edge weighs alike (not by its match's geometry)");
  number(g, "--loop-min-information-fraction", loops.min_information_fraction,
         "Every edge keeps at least this fraction of the sigmas' information in every direction");
  number(g, "--loop-judge-max-scans", loops.judge_max_scans,
         "After the relaxation each scan is judged again against this many nearest scans (0 = all near it)");
  number(g, "--loop-judge-max-visits", loops.judge_max_visits,
         "...of at most this many visits to its place: its own, the first, the next nearest in the drive (0 = all)");
  number(g, "--loop-visit-sweeps", loops.visit_sweeps,
         "A narrow-field timed sweep's loop match is against the sweeps within this many of the earlier one, before and "
         "after it, as one local map (0 = that sweep alone)");
  number(g, "--loop-max-misclosure-fraction", loops.max_misclosure_fraction,
         "A loop that closes further apart than this fraction of its drive makes its scan doubtful (0 = never)");
  number(g, "--loop-max-turn-deg-per-100m", loops.max_turn_deg_per_100m,
         "A loop match that turns its scan more than this per 100 m of drive is not closed (0 = never)");
  number(g, "--graph-translation-sigma-cm", loops.graph.translation_sigma_cm, "Pose graph: one edge's sigma (cm)");
  number(g, "--graph-rotation-sigma-rad", loops.graph.rotation_sigma_rad, "Pose graph: one edge's sigma (rad)");
  number(g, "--graph-max-iterations", loops.graph.max_iterations, "Pose graph: Gauss-Newton iterations at most");
  number(g, "--graph-min-update-cm", loops.graph.min_update_cm, "Pose graph: converged when no pose moves more");
}

void add_process_options(CLI::App& app, MapOptions& options) {
  app.add_option("--threads", options.threads, "Worker threads (0 = all cores)")->group(groups::kRun);
  app.add_option("--opencl-device", options.opencl_device,
                 "OpenCL device: a substring of 'platform / device' (same as MINEMAP_OPENCL_DEVICE)")
      ->group(groups::kRun);
}

Preset preset_argument(const std::vector<std::string>& args) {
  std::string preset;
  for (std::size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "--preset" && i + 1 < args.size()) preset = args[i + 1];
    if (args[i].rfind("--preset=", 0) == 0) preset = args[i].substr(9);
  }
  return value_named(kPresetNames, preset).value_or(Preset::kDefault);
}

void finish_settings(MapCommand& command) {
  const MapOptions& options = command.options;
  MappingSettings& settings = command.settings;
  if (options.no_filter) settings.filter_enabled = false;
  if (options.no_median) settings.filter.median_enabled = false;
  if (options.no_spacing_reduction) settings.filter.reduction_enabled = false;
  if (options.sparse_models) settings.dense_models = false;
  if (options.plain_icp) settings.icp.accelerate = false;
  if (options.no_health_check) settings.health.enabled = false;
  if (options.no_retry) settings.retry_bound_factors.clear();
  if (options.no_recovery) settings.recovery.enabled = false;
  if (options.no_first_sweep_fit) settings.motion.first_sweep_fit = false;
  if (options.provisional_all_points) settings.motion.provisional_probe = false;
  if (options.wide_coarse_all_points) settings.motion.wide_coarse_probe = false;
  if (options.moving_point_to_plane) settings.motion.plane_objective = true;
  if (options.no_loops) settings.loops.enabled = false;
  if (options.loop_edges_alike) settings.loops.information_from_geometry = false;
  if (!options.control.empty()) settings.control.keep_graph = true;
  settings.validate();
}

std::string mapping_options_text(const CLI::App& command) {
  std::istringstream config(command.config_to_str(false, false));
  std::vector<std::string> kept;
  for (std::string line; std::getline(config, line);) {
    if (line.empty()) continue;
    const std::string name = line.substr(0, line.find('='));
    const CLI::Option* option = nullptr;
    for (const CLI::Option* candidate : command.get_options()) {
      if (candidate->check_name(name) || candidate->check_name("--" + name)) option = candidate;
    }
    if (option != nullptr && changes_no_pose(option->get_group())) continue;
    kept.push_back(line);
  }
  std::sort(kept.begin(), kept.end());
  std::string text;
  for (const auto& k : kept) text += k + "\n";
  return text;
}

}  // namespace minemap::cli
