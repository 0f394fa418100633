#pragma once
// A moving LiDAR in the simulated mine: sweeps taken while the sensor moves on, each point measured
// at its own time from the pose the sensor had at that time. The scans therefore carry the motion
// distortion of a real moving sensor (at 10 m/s and 10 Hz a sweep's two ends lie 1 m apart), and
// per-point times to take it out again.
//
// Two sensors:
//   - kSpinning: a multi-beam spinning LiDAR (a 32-beam Velodyne/Ouster-like unit) on a vehicle. A
//     sweep turns through 360 deg of azimuth, column by column, clockwise seen from above, starting
//     and ending behind the sensor (so the sweep's seam is behind it and its middle looks ahead);
//     the beams of one column fire together and share one time.
//   - kHandheld: a forward-looking non-repetitive rosette (a Livox Mid-40/Avia-like unit: two
//     counter-rotating Risley prisms) carried by a walker, with the walker's sway; every point has
//     its own time.
//
// The drive follows the tilting survey's path (sim/trajectory.hpp's stops, taken as waypoints: the
// straight drive up the main entry, or the loop), at constant speed, on a Catmull-Rom curve through
// the waypoints parametrised by arc length, heading along the curve's tangent. The sensor's pose at
// time t is a pure function of t (SensorTrajectory).
//
// Frames, units and times (what the result holds):
//   - points: the sensor's own right-handed frame (x forward, y left, z up), cm, float, in the order
//     they were measured; each point in the frame the sensor had AT ITS OWN TIME (raw, distorted);
//   - time: t = 0 where the drive starts; sweep k spans [k T, (k + 1) T) with T = 1 / rate_hz and is
//     stamped at its MIDDLE, (k + 1/2) T; Scan::attributes.time_s holds each point's absolute time
//     (the stamp plus an offset in [-T/2, T/2));
//   - truth: T_world_sensor at each stamp, in a right-handed z-up world (cm) that is the mine's
//     3DTK frame turned by core/pose.hpp's threedtk_pose_to_right_handed (x along the drive, y left,
//     z up; the drive starts near the origin).
//
// Determinism: every random number comes from a counter stream keyed by (seed, sweep, column or
// point, beam) (sim_random.hpp), every point is computed independently into its own slot, so the
// survey is bit-identical for a seed whatever the thread count or schedule.
//
// Thread-safety: simulate_moving_survey is reentrant (TBB-parallel inside); a SensorTrajectory is
// immutable and its const members are safe from any number of threads.
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "minemap/core/name_table.hpp"
#include "minemap/core/pose.hpp"
#include "minemap/core/scan.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace minemap::sim {

class MineWorld;

enum class MovingSensor : std::uint8_t { kSpinning, kHandheld };
inline constexpr std::array<EnumName<MovingSensor>, 2> kMovingSensorNames{{
    {MovingSensor::kSpinning, "spinning"},
    {MovingSensor::kHandheld, "handheld"},
}};

/// The spinning multi-beam LiDAR and the vehicle that carries it.
struct SpinningLidarSettings {
  int beams = 32;                    ///< rings, evenly spread over the vertical field of view
  double min_elevation_deg = -25.0;  ///< ring 0
  double max_elevation_deg = 15.0;   ///< the last ring
  int columns = 900;                 ///< azimuth steps per revolution: 0.4 deg
  double mount_height_cm = 180.0;    ///< on a vehicle's roof, above the floor under its wheels
  double speed_mps = 10.0;           ///< the vehicle's default speed
};

/// The handheld rosette LiDAR and the walker who carries it.
struct HandheldLidarSettings {
  double points_per_second = 100000.0;  ///< 10 000 points per 0.1 s sweep
  double fov_deg = 70.0;                ///< full cone angle around the x axis
  /// The two prisms' turn rates (opposite senses). Their ratio is far from a small fraction, so the
  /// pattern does not repeat for seconds and fills the field of view over time.
  double prism_a_hz = 121.6;
  double prism_b_hz = 77.7;
  double carry_height_cm = 150.0;  ///< above the floor under the walker
  double speed_mps = 1.4;          ///< walking pace
  double stride_cm = 150.0;        ///< two steps: one period of the side-to-side sway
  double sway_roll_deg = 2.0;      ///< side-to-side, once per stride
  double sway_yaw_deg = 3.0;       ///< once per stride
  double sway_pitch_deg = 1.5;     ///< nodding, once per step
  double bob_cm = 2.0;             ///< up and down, once per step
};

/// What a moving LiDAR measures and how it moves. Defaults: see each field; `speed_mps` unset uses
/// the sensor's own default speed.
struct MovingSimulationSettings {
  MovingSensor sensor = MovingSensor::kSpinning;
  SpinningLidarSettings spinning;
  HandheldLidarSettings handheld;

  double rate_hz = 10.0;              ///< sweeps per second
  double range_noise_sigma_cm = 1.5;  ///< Gaussian range noise (as ScannerSettings)
  double min_range_cm = 50.0;         ///< nearer: no return (the point is absent)
  double max_range_cm = 8000.0;       ///< farther: no return

  /// Metres per second along the path; unset: the sensor's own (spinning.speed_mps or
  /// handheld.speed_mps). 0 stands still (then `sweeps` must be set).
  std::optional<double> speed_mps;
  /// Peak rate (deg/s) of an extra sinusoidal yaw weave on top of the path's heading (0: none); its
  /// rate is at its peak at t = 0, so even the first sweeps turn while they are taken.
  double turn_deg_s = 0.0;
  double turn_period_s = 2.0;  ///< period of that weave

  /// Number of sweeps; 0: as many as the path holds. The straight drive is lengthened (and the mine
  /// with it) when more are asked for; a loop ends where it began, so at most one lap is taken.
  int sweeps = 0;
  /// The mine, its seed and the path (loop_length_cm; mean_step_cm is the spacing of the waypoints).
  /// `scans`, `step_jitter` and `heading_sigma_deg` are not used: the waypoints lie evenly on the
  /// path and the heading follows the curve.
  MineSettings mine;

  /// Whether the scans carry drifting odometry in Scan::pose_cm (else the identity). The error
  /// model is the stop-and-go survey's (simulate_odometry), its per-step errors given for steps of
  /// MineSettings{}.mean_step_cm and scaled to the distance between sweeps: biases in proportion,
  /// random errors with its square root, so the drift per metre driven is the same.
  bool odometry = false;
  OdometrySettings odometry_errors;

  /// The speed used: speed_mps, or the sensor's default.
  double effective_speed_mps() const;
  /// Sweep period T = 1 / rate_hz.
  double sweep_period_s() const { return 1.0 / rate_hz; }
};

/// The true pose of the moving sensor at any time: a pure function of t. The sensor's height, pitch
/// and roll follow the floor under it (sim/trajectory.hpp's robot_pose_on_floor, for the walker
/// too); the handheld adds the walker's sway, a function of the distance walked.
/// Thread-safety: immutable; copies share the mine (read-only). A default-constructed one is empty
/// (only to be assigned); simulate_moving_survey makes the real ones.
class SensorTrajectory {
 public:
  SensorTrajectory() = default;
  /// T_world_sensor at time t (seconds since the drive began), right-handed z-up world, cm. Before
  /// t = 0 and after the path's end the sensor stands at the path's ends.
  Pose T_world_sensor(double t_s) const;
  /// The same pose in the mine's own 3DTK frame (T_world_sensor conjugated by right_handed_pose_to_3dtk).
  Pose T_world_sensor_3dtk(double t_s) const;
  /// Arc length along the path (x-z) at time t, cm.
  double distance_cm(double t_s) const;
  /// The path's length (x-z) and how long driving it takes (infinite at speed 0).
  double path_length_cm() const;
  double duration_s() const;
  /// The mine the sensor moves through (3DTK frame: ray casting, surfaces).
  const MineWorld& world() const;

  struct Impl;  ///< moving_lidar.cpp's: the mine, the path, the motion
  explicit SensorTrajectory(std::shared_ptr<const Impl> impl) : impl_(std::move(impl)) {}

 private:
  std::shared_ptr<const Impl> impl_;
};

/// A simulated moving-LiDAR survey.
struct MovingSurvey {
  /// One scan per sweep, named scanNNN: points in the sensor frame at each point's time (cm),
  /// attributes time_s (absolute) and intensity, ring for the spinning sensor; no slices. pose_cm is
  /// the odometry pose when settings.odometry, else the identity.
  std::vector<Scan> scans;
  std::vector<double> stamps_s;  ///< each sweep's middle
  std::vector<Pose> truth_cm;    ///< T_world_sensor at each stamp (right-handed z-up world, cm)
  std::vector<Pose> odometry_cm; ///< the scans' odometry poses (empty unless settings.odometry)
  double driven_distance_cm = 0.0;  ///< along the path, from the first sweep's start to the last one's end
  double speed_mps = 0.0;           ///< the speed driven
  SensorTrajectory trajectory;      ///< the true pose at any time
};

/// Simulates the survey. Throws std::invalid_argument on bad settings (non-positive rate, counts or
/// ranges, negative speed, speed 0 without a sweep count, a loop the mine cannot hold).
MovingSurvey simulate_moving_survey(const MovingSimulationSettings& settings);

}  // namespace minemap::sim
