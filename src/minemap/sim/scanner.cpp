#include "minemap/sim/scanner.hpp"

#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

#include "minemap/sim/mine_geometry.hpp"
#include "minemap/sim/sim_random.hpp"

namespace minemap::sim {
namespace {

constexpr double kRadPerDeg = std::numbers::pi / 180.0;

/// A depth discontinuity between neighbouring beams: more than this far apart, and more than
/// kMixedPixelRelativeJump of the range (grazing floors change range fast but smoothly).
constexpr double kMixedPixelJumpCm = 30.0;
constexpr double kMixedPixelRelativeJump = 0.1;
/// A mixed pixel's range lies this far between its own surface and its neighbour's.
constexpr double kMixedFractionMin = 0.15;
constexpr double kMixedFractionMax = 0.85;
/// Reflections: a mirror-like surface sends the beam on (long range) or a dust particle or wet
/// spot answers early (short range); the spurious range is the true one times a factor in these.
constexpr double kReflectionLongMin = 1.2;
constexpr double kReflectionLongMax = 2.5;
constexpr double kReflectionShortMin = 0.15;
constexpr double kReflectionShortMax = 0.8;

}  // namespace

ScannerModel::ScannerModel(const ScannerSettings& settings) : settings_(settings) {
  if (settings.points_per_slice < 1 || settings.slices < 1 || !(settings.slice_fov_deg > 0.0) ||
      !(settings.tilt_fov_deg >= 0.0) || !(settings.min_range_cm >= 0.0) ||
      !(settings.max_range_cm > settings.min_range_cm) || !(settings.range_noise_sigma_cm >= 0.0)) {
    throw std::invalid_argument("scanner settings: counts, fields of view and ranges must be positive");
  }
  for (int j = 0; j < settings.points_per_slice; ++j) {
    const double a = sweep_deg(j) * kRadPerDeg;
    sweep_sin_.push_back(std::sin(a));
    sweep_cos_.push_back(std::cos(a));
  }
  tilt_sin_.resize(static_cast<std::size_t>(settings.slices));
  tilt_cos_.resize(static_cast<std::size_t>(settings.slices));
  for (int i = 0; i < settings.slices; ++i) {
    const double b = tilt_deg(i) * kRadPerDeg;
    tilt_sin_[static_cast<std::size_t>(i)] = std::sin(b);
    tilt_cos_[static_cast<std::size_t>(i)] = std::cos(b);
  }
}

double ScannerModel::tilt_deg(int slice) const {
  const int n = settings_.slices;
  return n == 1 ? 0.0 : -0.5 * settings_.tilt_fov_deg + settings_.tilt_fov_deg * slice / (n - 1);
}

double ScannerModel::sweep_deg(int beam) const {
  const int n = settings_.points_per_slice;
  return n == 1 ? 0.0 : -0.5 * settings_.slice_fov_deg + settings_.slice_fov_deg * beam / (n - 1);
}

std::vector<double> ScannerModel::true_ranges(const MineWorld& world, const Pose& T_world_scan, int slice) const {
  const Eigen::Matrix3d rotation = T_world_scan.block<3, 3>(0, 0);
  const ViewPoint view = world.view_point(T_world_scan.block<3, 1>(0, 3));
  std::vector<double> ranges(static_cast<std::size_t>(points_per_slice()));
  for (int j = 0; j < points_per_slice(); ++j) {
    const RayHit hit = world.cast_ray(view, rotation * direction(slice, j), settings_.max_range_cm);
    ranges[static_cast<std::size_t>(j)] = hit.hit() ? hit.range_cm : std::numeric_limits<double>::infinity();
  }
  return ranges;
}

void ScannerModel::scan_slice(const MineWorld& world, const Pose& T_world_scan, int slice, std::uint64_t beam_key,
                              std::vector<Eigen::Vector3f>& out) const {
  const std::vector<double> ranges = true_ranges(world, T_world_scan, slice);
  const int n = points_per_slice();
  for (int j = 0; j < n; ++j) {
    const double r = ranges[static_cast<std::size_t>(j)];
    if (!std::isfinite(r)) continue;
    // A fixed number of draws per beam, in a fixed order, from the beam's own stream.
    CounterRng rng(stream_key(beam_key, static_cast<std::uint64_t>(j)));
    const double u_mixed = rng.uniform();
    const double mixed_fraction = rng.uniform(kMixedFractionMin, kMixedFractionMax);
    const double u_reflection = rng.uniform();
    const bool long_reflection = rng.uniform() < 0.5;
    const double u_factor = rng.uniform();
    const double noise = rng.normal();

    double range = r;
    // The neighbour across the larger depth jump, if any.
    double neighbour = std::numeric_limits<double>::quiet_NaN();
    double jump = 0.0;
    for (const int k : {j - 1, j + 1}) {
      if (k < 0 || k >= n) continue;
      const double rk = ranges[static_cast<std::size_t>(k)];
      if (std::isfinite(rk) && std::abs(rk - r) > jump) {
        jump = std::abs(rk - r);
        neighbour = rk;
      }
    }
    const bool at_edge = jump > kMixedPixelJumpCm && jump > kMixedPixelRelativeJump * r;
    if (at_edge && u_mixed < settings_.mixed_pixel_probability) {
      range = r + mixed_fraction * (neighbour - r);
    } else if (u_reflection < settings_.reflection_probability) {
      range *= long_reflection ? kReflectionLongMin + (kReflectionLongMax - kReflectionLongMin) * u_factor
                               : kReflectionShortMin + (kReflectionShortMax - kReflectionShortMin) * u_factor;
    }
    range += settings_.range_noise_sigma_cm * noise;
    if (range < settings_.min_range_cm || range > settings_.max_range_cm) continue;
    out.push_back((direction(slice, j) * range).cast<float>());
  }
}

}  // namespace minemap::sim
