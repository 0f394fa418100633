#pragma once
// The built-in simulated mine survey: a tilting 2D laser scanner (the paper's Groundhog robot)
// driving stop-and-go through a room-and-pillar mine. Deterministic for a seed.
#include <cstdint>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/core/scan.hpp"

namespace minemap::sim {

/// The scanner of the paper: 361 points per slice over 180 deg, 341 slices over 60 deg.
struct ScannerSettings {
  int points_per_slice = 361;
  double slice_fov_deg = 180.0;
  int slices = 341;
  double tilt_fov_deg = 60.0;
  double min_range_cm = 10.0;
  double max_range_cm = 8000.0;       ///< beyond: no return (the beam is absent from its slice)
  double range_noise_sigma_cm = 1.5;  ///< Gaussian range noise
  double mixed_pixel_probability = 0.3;     ///< at a depth jump, chance a beam returns a mixed range
  double reflection_probability = 0.002;    ///< per beam: a spurious long or short range
  double mount_height_cm = 80.0;            ///< scanner above the floor
};

/// The mine and the drive through it.
struct MineSettings {
  double drive_length_cm = 25000.0;  ///< 250 m, as the paper's run
  double elevation_gain_cm = 400.0;  ///< 4 m over the drive
  double mean_step_cm = 400.0;       ///< stop-and-go: metres between scan poses
  int scans = 0;                     ///< 0 = as many as the drive needs at mean_step_cm
  std::uint32_t seed = 1;
};

/// Odometry error model: realistic 6-DoF drift on top of the true motion.
struct OdometrySettings {
  double slip_scale = 0.03;             ///< systematic: odometry over-reports distance by 3 %
  double distance_sigma = 0.02;         ///< relative random error per step
  double yaw_bias_deg_per_step = 0.4;   ///< systematic heading drift
  double yaw_sigma_deg = 0.6;
  double pitch_roll_sigma_deg = 0.4;
  double lateral_sigma_cm = 5.0;
  double vertical_sigma_cm = 3.0;
};

struct SimulationSettings {
  ScannerSettings scanner;
  MineSettings mine;
  OdometrySettings odometry;
};

/// A simulated survey: scans carry odometry poses; truth holds the true T_world_scan per scan.
struct SimulatedSurvey {
  std::vector<Scan> scans;
  std::vector<Pose> truth_cm;
  double driven_distance_cm = 0.0;  ///< along the true trajectory
};

/// Simulates the survey, TBB-parallel over slices, bit-identical for a seed whatever the threads.
SimulatedSurvey simulate_mine_survey(const SimulationSettings& settings);

}  // namespace minemap::sim
