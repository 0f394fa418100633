#pragma once
// One sweep fitted as it was measured (not in the paper: its scanner stood still while it scanned).
// A moving LiDAR takes each point from the pose it had at that instant, so a sweep is not one rigid
// cloud but a short piece of trajectory. fit_sweep finds that piece against a model that is already
// right: the pose at the sweep's middle and the sensor's motion over the sweep, at constant velocity
// (the deskew's model, filter/deskew.hpp), by Gauss-Newton on the distances of the sweep's points to
// the model's planes, the pairs found again at each iteration as ICP does (continuous-time ICP,
// CT-ICP, Dellenbach et al. 2022, fits each sweep so; its two poses per sweep become one pose and a
// velocity here). The matcher uses it where the steps between sweeps cannot say how the sensor moved
// during one: the survey's first sweep, which has no step before it (slam/sweep_matching.cpp).
//
// A point taken at fraction f of the sweep (-0.5 to 0.5) is moved to the sweep's middle by
// exp(f log M), M the motion over the whole sweep, start to end, in the sensor's (file) frame:
// deskewed_points' motion. The fit widens in stages, the first from the middle quarter of the sweep:
// a start motion that is far off (the first sweep's, taken from the step into sweep 1, can be 30 deg
// short) puts the ends of the sweep out of reach of their pairs, the middle not.
//
// Units: centimetres and radians. Thread-safety: uses the backend, one thread at a time.
#include <span>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/core/pose.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/registration/match_information.hpp"

namespace minemap {

struct SweepFitSettings {
  float max_pair_dist_cm = PairingSettings{}.max_pair_dist_cm;  ///< pairs farther apart are left out
  /// The fit uses the points within stage/stages of the sweep's middle at stage 1, 2, ..., stages
  /// (4: the middle quarter, half, three quarters, all of it), each until it converges.
  int stages = 4;
  int max_iterations = 40;  ///< per stage; at the cap the next stage goes on from there
  /// An iteration converges when it moves the sweep's middle, start and end each less than this...
  double min_translation_step_cm = 0.01;
  double min_rotation_step_deg = 0.001;  ///< ...and turns each less than this
  int min_pairs = 250;                   ///< fewer pairs with a plane: the fit fails
  /// The last stage at its cap still converges where each of its last settle_iterations moved the
  /// sweep's middle, start and end less than this and turned them less than settled_step_deg: the
  /// pairs, found again each iteration, then change by a few at a time and the fit wanders by a
  /// millimetre about where it has settled without ever stepping under the least steps above (a
  /// -march=native build's FMA changed which of the simulated first sweeps did: 6 of 24 failed
  /// there, none in the plain build; docs/benchmarks.md). 0 iterations: off.
  double settled_step_cm = 0.5;
  double settled_step_deg = 0.05;
  int settle_iterations = 5;
  void validate() const;                 ///< throws std::invalid_argument
  bool operator==(const SweepFitSettings&) const = default;
};

/// One sweep's fit (fit_sweep).
struct SweepFit {
  Pose world_from_sweep = Pose::Identity();  ///< the sensor (file frame) at the sweep's middle, cm
  Pose motion = Pose::Identity();            ///< over the sweep, start to end, the sensor's frame, cm
  double rms_cm = 0.0;                       ///< of the last iteration's point-to-plane distances
  std::size_t pairs = 0;                     ///< the last iteration's pairs with a plane
  int iterations = 0;                        ///< over all stages
  bool converged = false;                    ///< the last stage (all of the sweep) converged with enough pairs
  bool settled = false;                      ///< ...by SweepFitSettings::settle_iterations, at its cap
};

/// Fits a sweep's points (`points_cm`, its file frame; `fractions` one each, filter/deskew.hpp's
/// SweepTiming::fraction) to `model`, whose planes (`model_normals`, in the model's frame) measure
/// each pair, from `start` (world from the sweep's middle) and `start_motion`. The model must come
/// from `backend`; `settings` are validated.
SweepFit fit_sweep(ComputeBackend& backend, std::span<const Eigen::Vector3d> points_cm, std::span<const float> fractions,
                   const WorldModel& model, const SurfaceNormals& model_normals, const Pose& start,
                   const Pose& start_motion, const SweepFitSettings& settings);

}  // namespace minemap
