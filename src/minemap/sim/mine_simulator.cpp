#include "minemap/sim/mine_simulator.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdio>
#include <limits>

#include "minemap/sim/mine_geometry.hpp"
#include "minemap/sim/scanner.hpp"
#include "minemap/sim/sim_random.hpp"
#include "minemap/sim/trajectory.hpp"

namespace minemap::sim {

namespace {

/// Scans [first, first + count) of the survey whose true and odometry poses are given. Every
/// (scan, slice) is an independent task writing its own buffer; randomness comes from per-beam
/// counter streams keyed by the scan's index, so a scan is the same bits whatever the thread count,
/// the schedule or the part it is simulated in.
std::vector<Scan> simulate_scans(const SimulationSettings& settings, const ScannerModel& scanner, const MineWorld& world,
                                 const std::vector<Pose>& truth_cm, const std::vector<Pose>& odometry,
                                 std::size_t first, std::size_t count) {
  const auto slices = static_cast<std::size_t>(scanner.slices());
  std::vector<std::vector<Eigen::Vector3f>> slice_points(count * slices);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, slice_points.size()),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t task = range.begin(); task != range.end(); ++task) {
                        const std::size_t scan = first + task / slices;
                        const std::size_t slice = task % slices;
                        auto& out = slice_points[task];
                        out.reserve(static_cast<std::size_t>(scanner.points_per_slice()));
                        scanner.scan_slice(world, truth_cm[scan], static_cast<int>(slice),
                                           key_for(settings.mine.seed, Stream::kBeam, scan, slice), out);
                      }
                    });
  std::vector<Scan> scans(count);
  tbb::parallel_for(std::size_t{0}, count, [&](std::size_t k) {
    Scan& s = scans[k];
    char name[32];
    std::snprintf(name, sizeof(name), "scan%03zu", first + k);
    s.name = name;
    s.pose_cm = odometry[first + k];
    std::size_t total = 0;
    for (std::size_t i = 0; i < slices; ++i) total += slice_points[k * slices + i].size();
    s.points_cm.reserve(total);
    s.slice_offsets.reserve(slices + 1);
    s.slice_offsets.push_back(0);
    for (std::size_t i = 0; i < slices; ++i) {
      auto& points = slice_points[k * slices + i];
      s.points_cm.insert(s.points_cm.end(), points.begin(), points.end());
      s.slice_offsets.push_back(static_cast<std::uint32_t>(s.points_cm.size()));
      std::vector<Eigen::Vector3f>().swap(points);  // release as we go
    }
  });
  return scans;
}

}  // namespace

SimulatedSurvey simulate_mine_survey_in_parts(const SimulationSettings& settings, std::size_t part_scans,
                                              const SimulatedPartSink& sink) {
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
  const std::size_t part = std::max<std::size_t>(1, part_scans);
  for (std::size_t first = 0; first < stops.size(); first += part) {
    std::vector<Scan> scans =
        simulate_scans(settings, scanner, world, survey.truth_cm, odometry, first, std::min(part, stops.size() - first));
    sink(scans, first, stops.size());
  }
  return survey;
}

SimulatedSurvey simulate_mine_survey(const SimulationSettings& settings) {
  std::vector<Scan> scans;
  SimulatedSurvey survey = simulate_mine_survey_in_parts(
      settings, std::numeric_limits<std::size_t>::max(), [&](std::vector<Scan>& part, std::size_t, std::size_t) { scans = std::move(part); });
  survey.scans = std::move(scans);
  return survey;
}

}  // namespace minemap::sim
