#pragma once
// The last stage of a survey's trip before the outputs (issue 29): the map tied to the mine's
// control. A surveyor's adjustment, in three steps:
//  1. Helmert: the map, as matched, moved rigidly onto the control points its scans observe
//     (Horn's closed form, the paper's, weighted by the points' sigmas).
//  2. The survey's pose graph (MappingResult::graph: every step as matched with its match's
//     information, and the loops' edges) adjusted with each observation as a prior with its sigma,
//     no scan fixed: the control bends the map where its drift is larger than the control's sigma.
//  3. Blunders: each control point is predicted by the map tied to the others; one farther from its
//     known position than ControlSettings::blunder_sigmas of the difference's sigma (its own and the
//     map's there) is left out, named, and its scans doubtful; the worst first, then again.
// The poses end in the grid's local frame (the grid less ControlTie::origin_cm), each scan's
// covariance from the adjusted graph; the outputs add the origin back.
//
// Frames: the grid is east, north, height (m; right-handed, z up). A survey in 3DTK's frame (a uos
// survey: x right, y up, z forward, left-handed) holds the grid as (-N, H, E), so that its outputs,
// turned as every uos survey's are, read east, north, height.
//
// Thread-safety: a pure function of its arguments (the covariances use TBB).
#include "minemap/io/control.hpp"
#include "minemap/slam/mapping_result.hpp"
#include "minemap/slam/mapping_settings.hpp"

namespace minemap {

/// Ties `result` (a finished run with MappingResult::graph) to `control`, moving its poses into the
/// grid and setting result.control. `survey_3dtk`: the survey is in 3DTK's frame (io::Survey::frame_3dtk).
/// `graph`: the relaxation's sigmas for edges without their own (MappingSettings::loops.graph).
/// Throws InputError naming the control file (and the line) for an observation of a scan the survey
/// does not hold, or fewer than 3 control points observed, or all of them on one line (a rigid tie
/// needs 3 not in a line); std::invalid_argument for a result without its graph.
void tie_to_control(MappingResult& result, const io::ControlFile& control, bool survey_3dtk,
                    const ControlSettings& settings, const PoseGraphSettings& graph);

/// A scan's sigma as a person reads it, from ScanOutcome::covariance: the translation's ellipsoid
/// (one sigma, its three semi-axes in cm, largest first, in the map's frame) and the rotation's
/// largest sigma (degrees).
struct ScanSigma {
  Eigen::Vector3d axes_cm = Eigen::Vector3d::Zero();
  double rotation_deg = 0.0;
};
ScanSigma scan_sigma(const ScanOutcome& scan);

/// The grid (east, north, height; any unit) in the survey's frame (survey_3dtk: 3DTK's axes), and back.
Eigen::Vector3d grid_to_survey_axes(const Eigen::Vector3d& grid, bool survey_3dtk);
Eigen::Vector3d survey_axes_to_grid(const Eigen::Vector3d& survey, bool survey_3dtk);

}  // namespace minemap
