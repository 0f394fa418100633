#pragma once
// Deskew (not in the paper: its scanner stood still while it scanned). A moving LiDAR measures each
// point at its own time during a sweep (a spinning sensor's 0.1 s turn, a handheld's frame), from
// the pose the sensor had at that time: at 10 m/s the two ends of a sweep lie a metre apart, and a
// cloud read as if taken at one instant is bent by the motion. Deskewing moves every point into the
// sensor's frame at one reference time, the sweep's middle, by the motion the sensor made in
// between, with the velocity constant across the sweep (KISS-ICP's model). Which motion that was,
// the matcher estimates (slam/motion_model.hpp); this file only applies it.
//
// Thread-safety: pure functions of their arguments.
#include <Eigen/Core>
#include <vector>

#include "minemap/core/name_table.hpp"
#include "minemap/core/pose.hpp"
#include "minemap/core/scan.hpp"

namespace minemap {

enum class DeskewMode {
  kAuto,  ///< scans whose points carry times within one sweep (at most max_sweep_s) are deskewed
  kOff,   ///< every scan is taken as measured at one instant
};
inline constexpr std::array<EnumName<DeskewMode>, 2> kDeskewModeNames{
    {{DeskewMode::kAuto, "auto"}, {DeskewMode::kOff, "off"}}};
const char* to_string(DeskewMode mode);
DeskewMode parse_deskew_mode(const std::string& text);  ///< a name of kDeskewModeNames

/// When in its sweep each point of a scan was taken.
struct SweepTiming {
  /// Per point (in Scan::points_cm's order): its time as a fraction of the sweep's duration from the
  /// sweep's middle, in [-0.5, 0.5]. Empty: the scan has no timing and is not deskewed.
  std::vector<float> fraction;
  double stamp_s = 0.0;     ///< the sweep's middle, on the file's clock (the time its pose is for)
  double duration_s = 0.0;  ///< first point to last
  bool empty() const { return fraction.empty(); }
};

/// The timing of `scan` from its points' times (Scan::attributes.time_s). Empty when it has none,
/// when all are equal, or when they span more than `max_sweep_s`: then the scan was not one sweep
/// of a moving sensor but taken standing (a tilting scanner or a TLS, over seconds or minutes), and
/// the motion between scans says nothing of the motion during one.
SweepTiming sweep_timing(const Scan& scan, double max_sweep_s);

/// `scan`'s points (its local frame, cm) moved into the sensor's frame at the sweep's middle.
/// `sweep_motion` is the sensor's motion over the whole sweep, start to end, in its own (the
/// file's) frame, cm; a point taken at fraction f moves by motion_fraction(sweep_motion, f). The
/// fractions are applied in 4096 steps across the sweep (at 1 m a sweep, 0.25 mm apart).
std::vector<Eigen::Vector3f> deskewed_points(const Scan& scan, const SweepTiming& timing, const Pose& sweep_motion);

}  // namespace minemap
