#include "minemap/sim/survey_control.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>

#include "minemap/sim/sim_random.hpp"

namespace minemap::sim {

SimulatedControl simulate_control(std::span<const Pose> truth_cm, std::span<const std::string> scan_names,
                                  const ControlSimulationSettings& settings) {
  const std::size_t scans = truth_cm.size();
  if (scan_names.size() != scans) throw std::invalid_argument("simulate_control: one name a scan");
  if (settings.stations < 3 || static_cast<std::size_t>(settings.stations) > scans) {
    throw std::invalid_argument("control: 3 stations at least, and at most one a scan (" + std::to_string(scans) +
                                " scans)");
  }
  SimulatedControl out;
  // Mine (3DTK axes: x right, y up, z forward) to east, north, height, then the grid's turn and shift.
  Eigen::Matrix3d axes;
  axes << 0, 0, 1,  // east = z
      -1, 0, 0,     // north = -x
      0, 1, 0;      // height = y
  const double angle = settings.grid_rotation_deg * std::numbers::pi / 180.0;
  const Eigen::Matrix3d turn = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  out.grid_from_mine_cm.block<3, 3>(0, 0) = turn * axes;
  out.grid_from_mine_cm.block<3, 1>(0, 3) =
      100.0 * Eigen::Vector3d(settings.offset_east_m, settings.offset_north_m, settings.offset_height_m);
  out.file.path = "control.txt";
  out.file.epsg = settings.epsg;
  CounterRng noise(key_for(settings.seed, Stream::kControl));
  const int stations = settings.stations;
  const int blunder = settings.blunder_m > 0.0 ? stations / 2 : -1;
  for (int s = 0; s < stations; ++s) {
    const std::size_t scan = static_cast<std::size_t>(
        std::llround(static_cast<double>(s) * static_cast<double>(scans - 1) / static_cast<double>(stations - 1)));
    // The mark: under the scanner's origin by its height, vertically (the mine's y).
    const Eigen::Vector3d origin = truth_cm[scan].block<3, 1>(0, 3);
    const Eigen::Vector3d mark_mine = origin - 100.0 * settings.instrument_height_m * Eigen::Vector3d::UnitY();
    const Eigen::Vector3d mark_grid_cm =
        out.grid_from_mine_cm.block<3, 3>(0, 0) * mark_mine + out.grid_from_mine_cm.block<3, 1>(0, 3);
    io::ControlPoint point;
    point.name = "S" + std::to_string(s + 1);
    point.sigma_horizontal_m = settings.sigma_horizontal_m;
    point.sigma_vertical_m = settings.sigma_vertical_m;
    point.grid_m = mark_grid_cm / 100.0 + Eigen::Vector3d(settings.sigma_horizontal_m * noise.normal(),
                                                          settings.sigma_horizontal_m * noise.normal(),
                                                          settings.sigma_vertical_m * noise.normal());
    if (s == blunder) {
      point.grid_m.x() += settings.blunder_m;
      out.blunder = point.name;
    }
    io::ControlObservation station;
    station.kind = io::ControlObservation::Kind::kStation;
    station.scan = scan_names[scan];
    station.point = out.file.points.size();
    station.instrument_height_cm = 100.0 * settings.instrument_height_m;
    out.file.points.push_back(point);
    out.file.observations.push_back(station);
  }
  return out;
}

}  // namespace minemap::sim
