#include "minemap/sim/survey_control.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "minemap/sim/mine_geometry.hpp"
#include "minemap/sim/sim_random.hpp"
#include "minemap/sim/trajectory.hpp"

namespace minemap::sim {

SimulatedControl simulate_control(std::span<const Pose> truth_cm, std::span<const std::string> scan_names,
                                  const ControlSimulationSettings& settings, const MineSettings& mine) {
  const std::size_t scans = truth_cm.size();
  if (scan_names.size() != scans) throw std::invalid_argument("simulate_control: one name a scan");
  if (settings.stations < 0 || settings.targets < 0 || settings.stations + settings.targets < 3 ||
      static_cast<std::size_t>(std::max(settings.stations, settings.targets)) > scans) {
    throw std::invalid_argument("control: 3 points at least (stations and targets), and at most one of each a scan (" +
                                std::to_string(scans) + " scans)");
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
  const auto evenly = [&](int i, int count) {
    if (count <= 1) return std::size_t{0};
    return static_cast<std::size_t>(
        std::llround(static_cast<double>(i) * static_cast<double>(scans - 1) / static_cast<double>(count - 1)));
  };
  for (int s = 0; s < stations; ++s) {
    const std::size_t scan = evenly(s, stations);
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
  if (settings.targets > 0) {
    // The mine the survey drove through, as simulate_mine_survey builds it (the straight drive's
    // mine reaches its last stop; a loop's lies within the drive's).
    const bool loop = mine.loop_length_cm > 0.0;
    const MineWorld world(mine, loop ? mine.drive_length_cm : plan_stops(mine).back().z_cm);
    for (int t = 0; t < settings.targets; ++t) {
      // Between the stations where both are asked: a target half a spacing on.
      const double place = settings.stations > 0 ? (static_cast<double>(t) + 0.5) / settings.targets : 0.0;
      const std::size_t scan = settings.stations > 0
                                   ? std::min(scans - 1, static_cast<std::size_t>(place * static_cast<double>(scans - 1)))
                                   : evenly(t, settings.targets);
      const Pose& pose = truth_cm[scan];
      const Eigen::Vector3d origin = pose.block<3, 1>(0, 3);
      // Right and left ribs in turn: targets all on one rib lie in a line along it, which leaves the
      // roll about it free (surveyors spread them for that reason).
      const Eigen::Vector3d right =
          pose.block<3, 3>(0, 0) * Eigen::Vector3d((t % 2 == 0) ? 1.0 : -1.0, 0.0, 0.0);  // 3DTK: x right
      const RayHit hit = world.cast_ray(origin, right.normalized(), 3000.0);
      if (!hit.hit()) continue;
      const Eigen::Vector3d on_rib = origin + hit.range_cm * right.normalized();
      io::ControlPoint point;
      point.name = "T" + std::to_string(t + 1);
      point.sigma_horizontal_m = settings.sigma_horizontal_m;
      point.sigma_vertical_m = settings.sigma_vertical_m;
      const Eigen::Vector3d grid_cm =
          out.grid_from_mine_cm.block<3, 3>(0, 0) * on_rib + out.grid_from_mine_cm.block<3, 1>(0, 3);
      point.grid_m = grid_cm / 100.0 + Eigen::Vector3d(settings.sigma_horizontal_m * noise.normal(),
                                                       settings.sigma_horizontal_m * noise.normal(),
                                                       settings.sigma_vertical_m * noise.normal());
      io::ControlObservation target;
      target.kind = io::ControlObservation::Kind::kTarget;
      target.scan = scan_names[scan];
      target.point = out.file.points.size();
      const Eigen::Vector3d in_scan = pose.block<3, 3>(0, 0).transpose() * (on_rib - origin);
      target.in_scan_cm = in_scan + 100.0 * settings.target_sigma_m *
                                        Eigen::Vector3d(noise.normal(), noise.normal(), noise.normal());
      out.file.points.push_back(point);
      out.file.observations.push_back(target);
    }
  }
  return out;
}

}  // namespace minemap::sim
