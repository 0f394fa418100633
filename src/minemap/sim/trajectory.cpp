#include "minemap/sim/trajectory.hpp"

#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "minemap/sim/mine_geometry.hpp"
#include "minemap/sim/sim_random.hpp"

namespace minemap::sim {
namespace {

constexpr double kRadPerDeg = std::numbers::pi / 180.0;

// The weave of the robot around the centre line: two incommensurate waves.
constexpr double kWeaveLongWavelengthCm = 6000.0;
constexpr double kWeaveShortWavelengthCm = 2300.0;
constexpr double kWeaveLongShare = 0.6;  ///< of lateral_wander_cm; the short wave gets the rest

// Groundhog: the front halves of two ATVs (wheel contact points of the robot).
constexpr double kWheelbaseCm = 150.0;
constexpr double kTrackCm = 120.0;

/// A loop starts at the first cross-cut at least this far ahead of z = 0.
constexpr double kLoopStartMinZCm = 300.0;

/// Stream ids inside Stream::kDrive.
constexpr std::uint64_t kWeaveStream = 0;
constexpr std::uint64_t kFirstStopStream = 1;

}  // namespace

int planned_scan_count(const MineSettings& settings) {
  if (settings.scans > 0) return settings.scans;
  if (!(settings.mean_step_cm > 0.0)) throw std::invalid_argument("mine settings: mean_step_cm must be positive");
  return static_cast<int>(std::lround(settings.drive_length_cm / settings.mean_step_cm)) + 1;
}

std::vector<ScanStop> plan_stops(const MineSettings& settings) {
  if (!(settings.mean_step_cm > 0.0) || settings.step_jitter < 0.0 || settings.step_jitter >= 0.5) {
    throw std::invalid_argument("mine settings: mean_step_cm > 0 and step_jitter in [0, 0.5) required");
  }
  const int count = planned_scan_count(settings);
  // The whole drive: stops evenly spaced so the last lands at drive_length_cm; an explicit scan
  // count keeps mean_step_cm.
  const double step = settings.scans > 0 || count < 2 ? settings.mean_step_cm
                                                      : settings.drive_length_cm / (count - 1);
  CounterRng weave(key_for(settings.seed, Stream::kDrive, kWeaveStream));
  const double phase_long = weave.uniform(0.0, 2.0 * std::numbers::pi);
  const double phase_short = weave.uniform(0.0, 2.0 * std::numbers::pi);
  const double amp_long = kWeaveLongShare * settings.lateral_wander_cm;
  const double amp_short = (1.0 - kWeaveLongShare) * settings.lateral_wander_cm;
  const double k_long = 2.0 * std::numbers::pi / kWeaveLongWavelengthCm;
  const double k_short = 2.0 * std::numbers::pi / kWeaveShortWavelengthCm;

  std::vector<ScanStop> stops(static_cast<std::size_t>(count));
  for (int k = 0; k < count; ++k) {
    CounterRng rng(key_for(settings.seed, Stream::kDrive, kFirstStopStream + static_cast<std::uint64_t>(k)));
    const double jitter = k == 0 ? 0.0 : settings.step_jitter * step * rng.uniform(-1.0, 1.0);
    const double heading_noise_deg = settings.heading_sigma_deg * rng.normal();
    const double z = k * step + jitter;
    const double x = amp_long * std::sin(k_long * z + phase_long) + amp_short * std::sin(k_short * z + phase_short);
    const double dx_dz = amp_long * k_long * std::cos(k_long * z + phase_long) +
                         amp_short * k_short * std::cos(k_short * z + phase_short);
    stops[static_cast<std::size_t>(k)] = {x, z, std::atan(dx_dz) / kRadPerDeg + heading_noise_deg};
  }
  return stops;
}

std::vector<ScanStop> plan_loop_stops(const MineSettings& settings, const MineWorld& world) {
  if (!(settings.mean_step_cm > 0.0) || settings.step_jitter < 0.0 || settings.step_jitter >= 0.5) {
    throw std::invalid_argument("mine settings: mean_step_cm > 0 and step_jitter in [0, 0.5) required");
  }
  const std::vector<double> crosscuts = world.drive_crosscuts_z(+1);
  const auto entries = world.entries();
  if (entries.size() < 2 || crosscuts.size() < 2) {
    throw std::invalid_argument("loop survey: the mine needs a parallel entry and two cross-cuts right of the drive");
  }
  const double entry_x = 0.5 * (entries[1].x_min_cm + entries[1].x_max_cm);  // the first entry right of the drive
  // Start at the first cross-cut ahead of z = 0; turn back at the one that makes the loop's
  // length closest to the one asked for, within the drive.
  std::size_t first = 0;
  while (first < crosscuts.size() && crosscuts[first] < kLoopStartMinZCm) ++first;
  std::size_t last = first + 1;
  for (std::size_t k = first + 1; k < crosscuts.size() && crosscuts[k] <= settings.drive_length_cm; ++k) {
    const auto length = [&](std::size_t j) { return 2.0 * (crosscuts[j] - crosscuts[first]) + 2.0 * entry_x; };
    if (std::abs(length(k) - settings.loop_length_cm) < std::abs(length(last) - settings.loop_length_cm)) last = k;
  }
  if (last >= crosscuts.size() || crosscuts[last] > settings.drive_length_cm) {
    throw std::invalid_argument("loop survey: no second cross-cut within the drive");
  }
  const double z_a = crosscuts[first], z_b = crosscuts[last];
  const std::array<Eigen::Vector2d, 5> corners = {Eigen::Vector2d(0.0, z_a), Eigen::Vector2d(0.0, z_b),
                                                  Eigen::Vector2d(entry_x, z_b), Eigen::Vector2d(entry_x, z_a),
                                                  Eigen::Vector2d(0.0, z_a)};
  double loop_cm = 0.0;
  for (std::size_t k = 1; k < corners.size(); ++k) loop_cm += (corners[k] - corners[k - 1]).norm();
  // The point at arc length s along the closed loop (x, z).
  const auto at = [&](double s) {
    s = std::fmod(std::fmod(s, loop_cm) + loop_cm, loop_cm);
    for (std::size_t k = 1; k < corners.size(); ++k) {
      const double leg = (corners[k] - corners[k - 1]).norm();
      if (s <= leg) return Eigen::Vector2d(corners[k - 1] + (s / leg) * (corners[k] - corners[k - 1]));
      s -= leg;
    }
    return corners.back();
  };
  const int steps = std::max(4, static_cast<int>(std::lround(loop_cm / settings.mean_step_cm)));
  const double step = loop_cm / steps;
  // One lap, back at the first scan's place; more scans than that drive round again (a patrol, each
  // lap a return to known places: a long survey with loops, bench/scale.sh --loop).
  int count = steps + 1;
  if (settings.scans > 0) count = settings.scans;
  std::vector<ScanStop> stops(static_cast<std::size_t>(count));
  for (int k = 0; k < count; ++k) {
    CounterRng rng(key_for(settings.seed, Stream::kDrive, kFirstStopStream + static_cast<std::uint64_t>(k)));
    const bool end = k % steps == 0;  // each lap starts where the first did
    const double s = k * step + (end ? 0.0 : settings.step_jitter * step * rng.uniform(-1.0, 1.0));
    const Eigen::Vector2d chord = at(s + 0.5 * step) - at(s - 0.5 * step);
    const double heading_noise_deg = settings.heading_sigma_deg * rng.normal();
    const Eigen::Vector2d p = at(s);
    stops[static_cast<std::size_t>(k)] = {p.x(), p.y(), std::atan2(chord.x(), chord.y()) / kRadPerDeg + heading_noise_deg};
  }
  return stops;
}

Pose robot_pose_on_floor(const MineWorld& world, const ScanStop& stop, double mount_height_cm) {
  const double yaw = stop.heading_deg * kRadPerDeg;
  const Eigen::Vector3d forward(std::sin(yaw), 0.0, std::cos(yaw));  // Ry(yaw) * z
  const Eigen::Vector3d right(std::cos(yaw), 0.0, -std::sin(yaw));   // Ry(yaw) * x
  const Eigen::Vector3d centre(stop.x_cm, 0.0, stop.z_cm);
  const auto wheel = [&](double along, double across) {
    const Eigen::Vector3d p = centre + along * forward + across * right;
    return world.floor_height(p.x(), p.z()).value;
  };
  const double half_base = 0.5 * kWheelbaseCm;
  const double half_track = 0.5 * kTrackCm;
  const double front_left = wheel(half_base, -half_track);
  const double front_right = wheel(half_base, half_track);
  const double rear_left = wheel(-half_base, -half_track);
  const double rear_right = wheel(-half_base, half_track);
  // Least-squares plane through the four contacts: rise per cm forward and per cm to the right.
  const double rise_forward = ((front_left + front_right) - (rear_left + rear_right)) / (2.0 * kWheelbaseCm);
  const double rise_right = ((front_right + rear_right) - (front_left + rear_left)) / (2.0 * kTrackCm);
  const double ground = 0.25 * (front_left + front_right + rear_left + rear_right);

  const Eigen::Vector3d body_forward = (forward + rise_forward * Eigen::Vector3d::UnitY()).normalized();
  const Eigen::Vector3d body_right = right + rise_right * Eigen::Vector3d::UnitY();
  const Eigen::Vector3d up = body_forward.cross(body_right).normalized();  // z x x = y (flat ground)
  Pose pose = Pose::Identity();
  pose.block<3, 1>(0, 0) = up.cross(body_forward);
  pose.block<3, 1>(0, 1) = up;
  pose.block<3, 1>(0, 2) = body_forward;
  pose.block<3, 1>(0, 3) = Eigen::Vector3d(stop.x_cm, ground, stop.z_cm) + mount_height_cm * up;
  return pose;
}

std::vector<Pose> simulate_odometry(const std::vector<Pose>& truth_cm, const OdometrySettings& odometry,
                                    std::uint32_t seed) {
  std::vector<Pose> odo;
  odo.reserve(truth_cm.size());
  for (std::size_t k = 0; k < truth_cm.size(); ++k) {
    if (k == 0) {
      odo.push_back(truth_cm[0]);  // the master scan fixes the frame
      continue;
    }
    const Pose motion = rigid_inverse(truth_cm[k - 1]) * truth_cm[k];  // in the robot's frame at k-1
    CounterRng rng(key_for(seed, Stream::kOdometry, k));
    const double scale = 1.0 + odometry.slip_scale + odometry.distance_sigma * rng.normal();
    const double lateral = odometry.lateral_sigma_cm * rng.normal();
    const double vertical = odometry.vertical_sigma_cm * rng.normal();
    EulerPose error;
    error.angles_deg.x() = odometry.pitch_roll_sigma_deg * rng.normal();  // pitch
    error.angles_deg.y() = odometry.yaw_bias_deg_per_step + odometry.yaw_sigma_deg * rng.normal();
    error.angles_deg.z() = odometry.pitch_roll_sigma_deg * rng.normal();  // roll
    Pose measured = Pose::Identity();
    measured.block<3, 3>(0, 0) = motion.block<3, 3>(0, 0) * euler_to_pose(error).block<3, 3>(0, 0);
    measured.block<3, 1>(0, 3) = scale * motion.block<3, 1>(0, 3) + Eigen::Vector3d(lateral, vertical, 0.0);
    odo.push_back(orthonormalised(odo.back() * measured));
  }
  return odo;
}

double path_length_cm(const std::vector<Pose>& poses_cm) {
  double length = 0.0;
  for (std::size_t k = 1; k < poses_cm.size(); ++k) {
    length += (poses_cm[k].block<3, 1>(0, 3) - poses_cm[k - 1].block<3, 1>(0, 3)).norm();
  }
  return length;
}

}  // namespace minemap::sim
