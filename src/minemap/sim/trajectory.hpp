#pragma once
// The drive: stop-and-go scan poses along the drive's centre line (true poses, the robot standing
// on the rough floor) and the odometry a real robot would have reported for them.
//
// Thread-safety: pure functions of their arguments; safe to call concurrently.
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace minemap::sim {

class MineWorld;

/// Where the robot stops to scan: on the floor at (x, z), heading `heading_deg` (3DTK's theta_y:
/// positive turns +z towards +x).
struct ScanStop {
  double x_cm = 0.0;
  double z_cm = 0.0;
  double heading_deg = 0.0;
};

/// Number of scans of a survey: settings.scans, or as many as drive_length_cm needs at mean_step_cm.
int planned_scan_count(const MineSettings& settings);

/// The stops: scan 0 at z = 0, then one every mean_step_cm (jittered) along +z, weaving gently
/// around the centre line. Stop k is the same whatever the number of scans.
std::vector<ScanStop> plan_stops(const MineSettings& settings);

/// The stops of a loop survey (settings.loop_length_cm > 0) in `world`: around the pillar block
/// right of the drive, one every mean_step_cm (jittered) along the loop, the last one back at the
/// first. Each heading follows the loop (the chord from half a step behind to half a step ahead,
/// so stops at a corner face between its two legs). settings.scans > 0 keeps the first stops only.
std::vector<ScanStop> plan_loop_stops(const MineSettings& settings, const MineWorld& world);

/// T_world_scan of a scanner `mount_height_cm` above the floor on a robot standing at `stop`:
/// its four wheels rest on the floor, so height, pitch and roll follow the floor under them.
Pose robot_pose_on_floor(const MineWorld& world, const ScanStop& stop, double mount_height_cm);

/// Odometry poses: scan 0 equals the truth; each later pose composes the previous odometry pose
/// with the true relative motion corrupted by `odometry`'s errors. Deterministic for the seed.
std::vector<Pose> simulate_odometry(const std::vector<Pose>& truth_cm, const OdometrySettings& odometry,
                                    std::uint32_t seed);

/// Length of the polyline through the poses' positions.
double path_length_cm(const std::vector<Pose>& poses_cm);

}  // namespace minemap::sim
