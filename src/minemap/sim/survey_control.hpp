#pragma once
// The simulated survey's control (issue 29): survey stations, known marks on the floor under some of
// the scan positions, in a mine grid rotated and shifted like a real one (a UTM-size offset), their
// coordinates measured with the control's sigma, and a blunder planted where asked. What
// `minemap simulate --control N` writes as DIR/control.txt, and what the tests tie maps to.
//
// Thread-safety: a pure function of its arguments.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/io/control.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace minemap::sim {

struct ControlSimulationSettings {
  /// Stations, at scan positions evenly along the survey, the first and the last scan's included.
  int stations = 0;
  /// Targets on the ribs (T1, T2, ...): a point of the right-hand rib (then the left, in turn), level with the scanner,
  /// picked in the scan nearest each of this many places evenly along the survey (its coordinates
  /// in that scan's frame, with target_sigma_m of noise) and known in the grid like a station.
  int targets = 0;
  double target_sigma_m = 0.005;
  /// The scanner's origin above the mark (its mount height: the mark is under it, on the floor).
  double instrument_height_m = 0.8;
  /// The control's sigma: stated in the file, and the noise drawn on each coordinate.
  double sigma_horizontal_m = 0.005;
  double sigma_vertical_m = 0.005;
  /// The grid: the mine's frame (east = its z, north = -x, height = y) turned by this about the
  /// vertical, then shifted by the offset (metres).
  double grid_rotation_deg = 23.0;
  double offset_east_m = 512345.25, offset_north_m = 7041876.5, offset_height_m = 1250.0;
  std::uint32_t epsg = 32633;  ///< written into the file (WGS 84 / UTM zone 33N)
  /// > 0: the middle station's coordinates are this far off, eastwards (a blunder, m).
  double blunder_m = 0.0;
  std::uint32_t seed = 1;
};

struct SimulatedControl {
  io::ControlFile file;
  /// The grid's true placement of the mine: grid (east, north, height; cm, absolute) of a mine point
  /// p (3DTK's axes, cm) is R * p + t: what a tie should find.
  Pose grid_from_mine_cm = Pose::Identity();
  std::string blunder;  ///< the point made wrong, if any
};

/// Stations over the scans whose true poses (3DTK frame, cm) are `truth_cm`, named `scan_names`,
/// and targets on the ribs of the mine `mine` (the survey's: the one the scans were simulated in).
/// Throws std::invalid_argument for fewer than 3 points in all, or more stations or targets than
/// there are scans.
SimulatedControl simulate_control(std::span<const Pose> truth_cm, std::span<const std::string> scan_names,
                                  const ControlSimulationSettings& settings, const MineSettings& mine = {});

}  // namespace minemap::sim
