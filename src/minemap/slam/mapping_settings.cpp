#include "minemap/slam/mapping_settings.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace minemap {

const char* to_string(MatchingMode mode) { return name_in(kMatchingModeNames, mode); }
MatchingMode parse_matching_mode(const std::string& text) { return parse_named(kMatchingModeNames, text, "mode"); }
const char* to_string(RefineSearch search) { return name_in(kRefineSearchNames, search); }
RefineSearch parse_refine_search(const std::string& text) {
  return parse_named(kRefineSearchNames, text, "refinement's search");
}
const char* to_string(Reduction reduction) { return name_in(kReductionNames, reduction); }
Reduction parse_reduction(const std::string& text) { return parse_named(kReductionNames, text, "reduction"); }
const char* to_string(Preset preset) { return name_in(kPresetNames, preset); }
Preset parse_preset(const std::string& text) { return parse_named(kPresetNames, text, "preset"); }
const char* to_string(MotionModel model) { return name_in(kMotionModelNames, model); }
MotionModel parse_motion_model(const std::string& text) { return parse_named(kMotionModelNames, text, "motion model"); }

IcpSettings MappingSettings::default_icp() {
  IcpSettings icp;
  icp.refine_pair_dist_fraction = 0.3f;
  icp.accelerate = true;
  icp.termination.min_translation_step_cm = 0.1;
  icp.termination.min_rotation_step_deg = 0.01;
  return icp;
}

IcpSettings MappingSettings::simultaneous_icp() {
  IcpSettings icp;
  icp.refine_pair_dist_fraction = 0.4f;
  icp.accelerate = true;
  return icp;
}

MappingSettings MappingSettings::simultaneous() {
  MappingSettings settings;
  settings.mode = MatchingMode::kSimultaneous;
  settings.reduction = Reduction::kSlices;
  settings.icp = simultaneous_icp();
  settings.loops.enabled = false;  // the relaxation is the paper's own
  return settings;
}

MappingSettings MappingSettings::paper() {
  MappingSettings settings = simultaneous();
  settings.icp = IcpSettings::paper();
  settings.dense_models = false;
  settings.max_relaxation_neighbours = 0;
  settings.max_relaxation_matches_per_scan = 0;
  settings.relaxation_min_step_cm = 0.0;
  settings.relaxation_min_step_deg = 0.0;
  return settings;
}

MappingSettings MappingSettings::preset(Preset preset) {
  switch (preset) {
    case Preset::kDefault: return {};
    case Preset::kSimultaneous: return simultaneous();
    case Preset::kPaper: return paper();
  }
  return {};
}

IcpSettings MappingSettings::pairwise_icp() const {
  IcpSettings pairwise = icp;
  pairwise.termination.min_pairs = std::min(pairwise.termination.min_pairs, min_overlap_pairs);
  return pairwise;
}

int MappingSettings::min_pairs_for(std::size_t data_points) const {
  const int pairwise = pairwise_icp().termination.min_pairs;
  const double scaled = std::ceil(min_overlap_fraction * static_cast<double>(data_points));
  if (scaled >= pairwise) return pairwise;
  return std::max(3, static_cast<int>(scaled));
}

IcpSettings MappingSettings::relaxation_icp() const {
  IcpSettings relaxation = pairwise_icp();
  if (relaxation_min_step_cm > 0.0) relaxation.termination.min_translation_step_cm = relaxation_min_step_cm;
  if (relaxation_min_step_deg > 0.0) relaxation.termination.min_rotation_step_deg = relaxation_min_step_deg;
  return relaxation;
}

bool MappingSettings::voxel_models() const {
  return dense_models && model_voxel_cm > 0.0f && model_voxel_cm < voxel_cm;
}

bool MappingSettings::needs_planes() const {
  return health.enabled || (loops.enabled && loops.information_from_geometry) || motion.plane_objective;
}

void MappingSettings::validate() const {
  filter.validate();
  icp.validate();
  if (tree.bucket_size < 1) throw std::invalid_argument("kd-tree bucket size must be >= 1");
  if (unstructured_point_stride < 1) throw std::invalid_argument("point stride must be >= 1");
  if (model_slice_stride < 1) throw std::invalid_argument("model slice stride must be >= 1");
  if (min_overlap_pairs < 0) throw std::invalid_argument("the overlap threshold must be >= 0 pairs");
  if (max_relaxation_matches_per_scan < 0) throw std::invalid_argument("the relaxation cap must be >= 0");
  if (!(plane_cell_cm > 0.0f) || !std::isfinite(plane_cell_cm)) {
    throw std::invalid_argument("the planes' cell must be a finite length > 0 cm");
  }
  if (!(relaxation_min_step_cm >= 0.0) || !(relaxation_min_step_deg >= 0.0) || !std::isfinite(relaxation_min_step_cm) ||
      !std::isfinite(relaxation_min_step_deg)) {
    throw std::invalid_argument("the relaxation's convergence thresholds must be finite and >= 0");
  }
  if (max_relaxation_neighbours < 0) throw std::invalid_argument("the relaxation's neighbour cap must be >= 0");
  for (const float factor : retry_bound_factors) {
    if (!(factor > 1.0f) || !std::isfinite(factor)) throw std::invalid_argument("retry bound factors must be > 1");
  }
  if (!(max_retry_bound_cm > 0.0f)) throw std::invalid_argument("the widest retry bound must be > 0 cm");
  if (!(min_overlap_fraction >= 0.0) || !(min_overlap_fraction <= 1.0)) {
    throw std::invalid_argument("the overlap fraction must be in [0, 1]");
  }
  loops.validate();
  motion.validate();
  recovery.validate();
  control.validate();
  health.validate();
  if (reduction == Reduction::kVoxel && (!(voxel_cm > 0.0f) || !std::isfinite(voxel_cm))) {
    throw std::invalid_argument("the voxel size must be a finite length > 0 cm");
  }
  if (!(model_voxel_cm >= 0.0f) || !std::isfinite(model_voxel_cm)) {
    throw std::invalid_argument("the model voxel size must be a finite length >= 0 cm");
  }
  if (!(metascan_margin_cm >= 0.0) || !std::isfinite(metascan_margin_cm)) {
    throw std::invalid_argument("the metascan margin must be a finite length >= 0 cm");
  }
}

void RecoverySettings::validate() const {
  global.validate();
  if (!(reach_cm > 0.0) || !std::isfinite(reach_cm)) throw std::invalid_argument("recovery: reach_cm must be > 0");
}

void MotionSettings::validate() const {
  if (!(adaptive_bound_sigmas >= 0.0) || !std::isfinite(adaptive_bound_sigmas)) {
    throw std::invalid_argument("the adaptive bound's sigmas must be finite and >= 0");
  }
  if (adaptive_bound_window < 1) throw std::invalid_argument("the adaptive bound's window must be >= 1 scan");
  if (!(max_sweep_s > 0.0)) throw std::invalid_argument("the longest sweep must be > 0 s");
  if (!(wide_coarse_kernel_fraction >= 0.0) || !std::isfinite(wide_coarse_kernel_fraction)) {
    throw std::invalid_argument("the coarse stage's kernel must be a finite fraction >= 0 of the bound (0 = off)");
  }
  if (!(local_map_cell_cm >= 0.0) || !std::isfinite(local_map_cell_cm)) {
    throw std::invalid_argument("the local map's cell must be a finite length >= 0 cm");
  }
  if (local_map_sweeps < 1) throw std::invalid_argument("a local map serves at least 1 sweep");
  if (!(provisional_step_factor >= 1.0) || !std::isfinite(provisional_step_factor)) {
    throw std::invalid_argument("the provisional match's step factor must be finite and >= 1");
  }
  if (!(slide_constraint >= 0.0 && slide_constraint <= 1.0)) {
    throw std::invalid_argument("the slide test's constraint must be a fraction in [0, 1] (0 = off)");
  }
  if (!(slide_rms_factor > 0.0 && slide_rms_factor <= 1.0)) {
    throw std::invalid_argument("the slide test's RMS factor must be in (0, 1]");
  }
  if (!(sweep_start_spring_pairs >= 0.0) || !std::isfinite(sweep_start_spring_pairs)) {
    throw std::invalid_argument("the sweeps' start spring must be a finite weight >= 0 (in pairs; 0 = off)");
  }
  if (!(sweep_spring_full_error_cm > 0.0) || !std::isfinite(sweep_spring_full_error_cm)) {
    throw std::invalid_argument("the sweeps' spring's full-weight error must be a finite length > 0 cm");
  }
  if (!(sweep_spring_max_field_deg > 0.0 && sweep_spring_max_field_deg <= 360.0)) {
    throw std::invalid_argument("the sweeps' spring's widest field must be in (0, 360] degrees");
  }
  if (!(sprung_release_cm > 0.0) || !std::isfinite(sprung_release_cm)) {
    throw std::invalid_argument("a held match's release distance must be a finite length > 0 cm");
  }
  if (!(weak_step_constraint >= 0.0 && weak_step_constraint <= 1.0)) {
    throw std::invalid_argument("the weak step's constraint must be a fraction in [0, 1] (0 = off)");
  }
  if (weak_step_window < 1) throw std::invalid_argument("the weak step's window must be at least 1 scan");
  if (!(max_unpinned_turn_deg >= 0.0) || !std::isfinite(max_unpinned_turn_deg)) {
    throw std::invalid_argument("the unpinned turn's limit must be a finite number of degrees >= 0 (0 = off)");
  }
  if (!(unpinned_turn_window_s > 0.0) || !std::isfinite(unpinned_turn_window_s)) {
    throw std::invalid_argument("the unpinned turn's window must be a finite number of seconds > 0");
  }
  first_sweep_fit_settings.validate();
  if (!(unfitted_first_sweep_max_turn_deg >= 0.0) || !std::isfinite(unfitted_first_sweep_max_turn_deg)) {
    throw std::invalid_argument("the unfitted first sweep's largest turn must be a finite number >= 0 of degrees");
  }
  if (first_sweep_rematch_scans < 0) {
    throw std::invalid_argument("the first sweep's second match comes after a number of sweeps >= 0 (0 = off)");
  }
  if (!(unpinned_turn_constraint >= 0.0 && unpinned_turn_constraint <= 1.0)) {
    throw std::invalid_argument("the unpinned turn's constraint must be a fraction in [0, 1]");
  }
}

void ControlSettings::validate() const {
  if (!(blunder_sigmas > 0.0) || !std::isfinite(blunder_sigmas)) {
    throw std::invalid_argument("a control blunder's least distance must be a finite number of sigmas > 0");
  }
  if (!(sigma_scale > 0.0) || !std::isfinite(sigma_scale)) {
    throw std::invalid_argument("the map's sigma scale must be a finite number > 0");
  }
  if (!(level_sigma_deg > 0.0) || !std::isfinite(level_sigma_deg)) {
    throw std::invalid_argument("the control's level prior must be a finite sigma > 0 deg");
  }
}

void LoopClosureSettings::validate() const {
  if (min_scan_gap < 2) throw std::invalid_argument("a loop must join scans at least 2 apart");
  if (judge_max_scans < 0) throw std::invalid_argument("the judging after a loop takes 0 (all) or more scans");
  if (judge_max_visits < 0) throw std::invalid_argument("the judging after a loop takes 0 (all) or more visits");
  if (visit_sweeps < 0) throw std::invalid_argument("a loop match's visit takes 0 (the one sweep) or more sweeps");
  if (!(max_distance_cm > 0.0) || !std::isfinite(max_distance_cm)) {
    throw std::invalid_argument("the loop candidates' distance must be a finite length > 0 cm");
  }
  if (!(max_return_path_cm >= 0.0) || !std::isfinite(max_return_path_cm)) {
    throw std::invalid_argument("a loop return's longest drive must be a finite length >= 0 cm (0: never cut)");
  }
  if (!(min_path_cm >= 0.0) || !std::isfinite(min_path_cm)) {
    throw std::invalid_argument("a loop's least drive must be a finite length >= 0 cm");
  }
  for (const float factor : bound_factors) {
    if (!(factor >= 1.0f) || !std::isfinite(factor)) throw std::invalid_argument("loop bound factors must be >= 1");
  }
  if (!(max_misclosure_fraction >= 0.0) || !std::isfinite(max_misclosure_fraction)) {
    throw std::invalid_argument("a loop's largest misclosure must be a finite fraction >= 0 of its drive");
  }
  if (!(max_turn_deg_per_100m >= 0.0) || !std::isfinite(max_turn_deg_per_100m)) {
    throw std::invalid_argument("a loop match's largest turn must be a finite number >= 0 of degrees per 100 m");
  }
  if (!(graph.translation_sigma_cm > 0.0) || !(graph.rotation_sigma_rad > 0.0) || graph.max_iterations < 1) {
    throw std::invalid_argument("the pose graph needs sigmas > 0 and at least one iteration");
  }
  if (!(min_information_fraction > 0.0) || !(min_information_fraction <= 1.0)) {
    throw std::invalid_argument("the information floor must be in (0, 1]");
  }
}

}  // namespace minemap
