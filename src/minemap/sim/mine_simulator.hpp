#pragma once
// The built-in simulated mine survey: a tilting 2D laser scanner (the paper's Groundhog robot)
// driving stop-and-go through a room-and-pillar mine. Deterministic for a seed.
#include <cstddef>
#include <cstdint>
#include <functional>
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
///
/// The mine is a room-and-pillar coal mine like the paper's Mathies mine: a main entry (the drive,
/// along world +z) between two rows of pillars, parallel entries beyond them, cross-cuts at
/// irregular spacing, timber sets, rails and rubble. Every dimension below is a mean or a range the
/// seed draws from. The mine depends on the seed and on these settings only, never on `scans`
/// (unless the drive runs past drive_length_cm, which lengthens the mine), so a short survey is the
/// start of the long one.
struct MineSettings {
  double drive_length_cm = 25000.0;  ///< 250 m, as the paper's run
  double elevation_gain_cm = 400.0;  ///< 4 m over the drive
  double mean_step_cm = 400.0;       ///< stop-and-go: metres between scan poses
  int scans = 0;                     ///< 0 = as many as the drive (or one lap of a loop) needs at mean_step_cm; a loop's extra scans drive more laps
  std::uint32_t seed = 1;

  // --- layout (x across the drive, y up, z along the drive; cm) ---
  double main_entry_width_cm = 470.0;  ///< rib to rib of the drive
  double entry_height_cm = 250.0;      ///< mean floor-to-roof height (the seam)
  int parallel_entries_per_side = 2;   ///< entries beyond the pillar rows on each side
  double parallel_entry_width_min_cm = 420.0;
  double parallel_entry_width_max_cm = 540.0;
  double pillar_width_min_cm = 800.0;  ///< across the entries
  double pillar_width_max_cm = 1300.0;
  double crosscut_spacing_min_cm = 1500.0;  ///< centre to centre along a pillar row
  double crosscut_spacing_max_cm = 2500.0;
  double crosscut_width_min_cm = 400.0;
  double crosscut_width_max_cm = 520.0;
  double timber_set_spacing_min_cm = 250.0;  ///< roof bars with posts along the drive
  double timber_set_spacing_max_cm = 450.0;
  double rubble_pile_spacing_min_cm = 600.0;  ///< along each entry
  double rubble_pile_spacing_max_cm = 2200.0;
  bool rails = true;              ///< a mine railway down the drive
  bool broken_bar_at_end = true;  ///< a roof bar draping diagonally just past the last scan pose
  double wall_roughness_cm = 4.0;     ///< amplitude of the 3 m bumps on the ribs (finer ones smaller)
  double floor_roughness_cm = 2.0;    ///< same for the floor
  double ceiling_roughness_cm = 3.0;  ///< same for the roof

  // --- the drive ---
  /// 0: the straight drive up the main entry. > 0: a loop of about this length around the pillars
  /// right of the drive instead: up the drive, right through a cross-cut, back down the parallel
  /// entry and through an earlier cross-cut to where it began. Its last stop is its first again
  /// (same place and heading, up to the noise), so a mapper's first and last scans must agree.
  double loop_length_cm = 0.0;
  double step_jitter = 0.1;           ///< scan positions vary by +-10 % of a step around even spacing
  double lateral_wander_cm = 30.0;    ///< the robot's weave around the drive's centre line
  double heading_sigma_deg = 1.0;     ///< the robot's heading around the path direction
};

/// Odometry error model: realistic 6-DoF drift on top of the true motion. Each step's relative
/// motion (in the robot's frame) is corrupted: translation scaled by 1 + slip_scale +
/// N(0, distance_sigma) plus lateral and vertical noise; rotation composed with an error of
/// N(0, pitch_roll_sigma) pitch and roll and yaw_bias + N(0, yaw_sigma) yaw.
///
/// The defaults give, over the 250 m drive, an end-point error of about 12-23 m and 5-9 deg (seeds
/// 1-5) while one step's error stays below about 20 cm and 1 deg, which is what the mapper has to
/// correct per scan pair (it carries the previous scan's correction forward, as 3DTK does).
struct OdometrySettings {
  double slip_scale = 0.02;             ///< systematic: odometry over-reports distance by 2 %
  double distance_sigma = 0.01;         ///< relative random error per step
  double yaw_bias_deg_per_step = 0.1;   ///< systematic heading drift
  double yaw_sigma_deg = 0.3;
  double pitch_roll_sigma_deg = 0.2;
  double lateral_sigma_cm = 3.0;
  double vertical_sigma_cm = 2.0;
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

/// Receives a part of a simulated survey of `total` scans: its scans (with their points; the sink may
/// take them), the first of which is the survey's scan `first`.
using SimulatedPartSink = std::function<void(std::vector<Scan>& part, std::size_t first, std::size_t total)>;
/// The same survey a part of `part_scans` scans at a time, each handed to `sink` and dropped after:
/// a survey of any length in the memory of one part (`minemap simulate`). The same scans, bit for
/// bit, as simulate_mine_survey's; the result holds the truth and the distance, no scans.
SimulatedSurvey simulate_mine_survey_in_parts(const SimulationSettings& settings, std::size_t part_scans,
                                              const SimulatedPartSink& sink);

}  // namespace minemap::sim
