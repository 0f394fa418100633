#include "minemap/sim/mine_simulator.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cstdio>

#include "minemap/sim/mine_geometry.hpp"
#include "minemap/sim/scanner.hpp"
#include "minemap/sim/sim_random.hpp"
#include "minemap/sim/trajectory.hpp"

namespace minemap::sim {

SimulatedSurvey simulate_mine_survey(const SimulationSettings& settings) {
  const ScannerModel scanner(settings.scanner);
  // A loop lies inside the drive's mine; the straight drive may run past it (and lengthen it).
  const bool loop = settings.mine.loop_length_cm > 0.0;
  const std::vector<ScanStop> straight = loop ? std::vector<ScanStop>{} : plan_stops(settings.mine);
  const MineWorld world(settings.mine, loop ? settings.mine.drive_length_cm : straight.back().z_cm);
  const std::vector<ScanStop> stops = loop ? plan_loop_stops(settings.mine, world) : straight;

  SimulatedSurvey survey;
  survey.truth_cm.reserve(stops.size());
  for (const ScanStop& stop : stops) {
    survey.truth_cm.push_back(robot_pose_on_floor(world, stop, settings.scanner.mount_height_cm));
  }
  survey.driven_distance_cm = path_length_cm(survey.truth_cm);
  const std::vector<Pose> odometry = simulate_odometry(survey.truth_cm, settings.odometry, settings.mine.seed);

  // Every (scan, slice) is an independent task writing its own buffer; randomness comes from
  // per-beam counter streams, so the result is bit-identical for any thread count or schedule.
  const std::size_t scan_count = stops.size();
  const auto slices = static_cast<std::size_t>(scanner.slices());
  std::vector<std::vector<Eigen::Vector3f>> slice_points(scan_count * slices);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, slice_points.size()),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t task = range.begin(); task != range.end(); ++task) {
                        const std::size_t scan = task / slices;
                        const std::size_t slice = task % slices;
                        auto& out = slice_points[task];
                        out.reserve(static_cast<std::size_t>(scanner.points_per_slice()));
                        scanner.scan_slice(world, survey.truth_cm[scan], static_cast<int>(slice),
                                           key_for(settings.mine.seed, Stream::kBeam, scan, slice), out);
                      }
                    });

  survey.scans.resize(scan_count);
  tbb::parallel_for(std::size_t{0}, scan_count, [&](std::size_t scan) {
    Scan& s = survey.scans[scan];
    char name[32];
    std::snprintf(name, sizeof(name), "scan%03zu", scan);
    s.name = name;
    s.pose_cm = odometry[scan];
    std::size_t total = 0;
    for (std::size_t i = 0; i < slices; ++i) total += slice_points[scan * slices + i].size();
    s.points_cm.reserve(total);
    s.slice_offsets.reserve(slices + 1);
    s.slice_offsets.push_back(0);
    for (std::size_t i = 0; i < slices; ++i) {
      auto& points = slice_points[scan * slices + i];
      s.points_cm.insert(s.points_cm.end(), points.begin(), points.end());
      s.slice_offsets.push_back(static_cast<std::uint32_t>(s.points_cm.size()));
      std::vector<Eigen::Vector3f>().swap(points);  // release as we go
    }
  });
  return survey;
}

}  // namespace minemap::sim
