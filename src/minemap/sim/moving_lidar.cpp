#include "minemap/sim/moving_lidar.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include "minemap/sim/mine_geometry.hpp"
#include "minemap/sim/sim_random.hpp"
#include "minemap/sim/trajectory.hpp"

namespace minemap::sim {
namespace {

constexpr double kRadPerDeg = std::numbers::pi / 180.0;
constexpr double kCmPerM = 100.0;

/// Ids inside the simulator's streams that the stop-and-go survey never uses (its ids there are
/// scan, slice and stop indices, far below these), so the two surveys' streams never meet.
constexpr std::uint64_t kMovingBeamId = 0x4d4f56494e47ULL;  ///< under Stream::kBeam: one per ray
constexpr std::uint64_t kSwayId = 0x53574159ULL;            ///< under Stream::kDrive: the sway's phases

/// Arc-length table of the path: chords per Catmull-Rom segment. 16 chords of a 4 m segment are
/// 25 cm long; their sagitta on the gentlest curves of the drive is far below a millimetre.
constexpr int kChordsPerSegment = 16;

/// Points of one sweep computed by one task: enough work to amortise the task, small enough to
/// spread a sweep over the cores.
constexpr int kSamplesPerTask = 64;

/// Reflectivity of what a beam hits (intensity = reflectivity x incidence x range falloff): the
/// smooth timber, steel and rubble faces return more than the dull rock.
constexpr double kFloorReflectivity = 0.25;
constexpr double kRoofReflectivity = 0.30;
constexpr double kRibReflectivity = 0.35;
constexpr double kObjectReflectivity = 0.55;
/// Ribs and objects: the incidence is not known from the ray cast; a typical value stands in.
constexpr double kUnknownIncidenceCos = 0.7;
constexpr double kIntensityFalloffCm = 6000.0;  ///< e-folding range of the returned intensity
constexpr double kIntensityScale = 255.0;       ///< 8-bit-like values, as most drivers publish
constexpr double kSpeckle = 0.05;               ///< +-5 % from point to point

/// A path through waypoints (x, z in the mine's 3DTK frame, cm): uniform Catmull-Rom segments, C1,
/// evaluated by arc length. Open paths mirror their ends; closed ones (first == last) wrap.
class WaypointPath {
 public:
  WaypointPath(std::vector<Eigen::Vector2d> points, bool closed) : points_(std::move(points)), closed_(closed) {
    if (points_.size() < 2) throw std::invalid_argument("moving survey: the path needs two waypoints");
    const int segments = static_cast<int>(points_.size()) - 1;
    cumulative_cm_.reserve(static_cast<std::size_t>(segments * kChordsPerSegment + 1));
    cumulative_cm_.push_back(0.0);
    Eigen::Vector2d previous = points_.front();
    for (int i = 0; i < segments; ++i) {
      for (int k = 1; k <= kChordsPerSegment; ++k) {
        const Eigen::Vector2d p = evaluate(i, static_cast<double>(k) / kChordsPerSegment, nullptr);
        cumulative_cm_.push_back(cumulative_cm_.back() + (p - previous).norm());
        previous = p;
      }
    }
  }

  double length_cm() const { return cumulative_cm_.back(); }

  /// Position (x, z) and unit tangent at arc length s (clamped to the path).
  void at(double s_cm, Eigen::Vector2d* position, Eigen::Vector2d* tangent) const {
    s_cm = std::clamp(s_cm, 0.0, length_cm());
    const auto upper = std::upper_bound(cumulative_cm_.begin(), cumulative_cm_.end(), s_cm);
    const auto last_chord = static_cast<std::ptrdiff_t>(cumulative_cm_.size()) - 2;
    const std::ptrdiff_t chord = std::clamp<std::ptrdiff_t>(upper - cumulative_cm_.begin() - 1, 0, last_chord);
    const double lo = cumulative_cm_[static_cast<std::size_t>(chord)];
    const double span = cumulative_cm_[static_cast<std::size_t>(chord) + 1] - lo;
    const double fraction = span > 0.0 ? std::clamp((s_cm - lo) / span, 0.0, 1.0) : 0.0;
    const int segment = static_cast<int>(chord / kChordsPerSegment);
    const double u = (static_cast<double>(chord % kChordsPerSegment) + fraction) / kChordsPerSegment;
    Eigen::Vector2d derivative;
    *position = evaluate(segment, u, &derivative);
    const double norm = derivative.norm();
    *tangent = norm > 0.0 ? Eigen::Vector2d(derivative / norm) : Eigen::Vector2d(0.0, 1.0);
  }

 private:
  /// Waypoint i, extended past the ends: wrapped (closed) or mirrored (open).
  Eigen::Vector2d point(int i) const {
    const int n = static_cast<int>(points_.size());
    if (i >= 0 && i < n) return points_[static_cast<std::size_t>(i)];
    if (closed_) return points_[static_cast<std::size_t>(i < 0 ? n - 2 : 1)];  // first == last
    return i < 0 ? Eigen::Vector2d(2.0 * points_[0] - points_[1])
                 : Eigen::Vector2d(2.0 * points_[static_cast<std::size_t>(n - 1)] - points_[static_cast<std::size_t>(n - 2)]);
  }

  Eigen::Vector2d evaluate(int segment, double u, Eigen::Vector2d* derivative) const {
    const Eigen::Vector2d p0 = point(segment - 1), p1 = point(segment), p2 = point(segment + 1), p3 = point(segment + 2);
    const Eigen::Vector2d a = 2.0 * p1;
    const Eigen::Vector2d b = p2 - p0;
    const Eigen::Vector2d c = 2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3;
    const Eigen::Vector2d d = -p0 + 3.0 * p1 - 3.0 * p2 + p3;
    if (derivative) *derivative = 0.5 * (b + 2.0 * u * c + 3.0 * u * u * d);
    return 0.5 * (a + u * (b + u * (c + u * d)));
  }

  std::vector<Eigen::Vector2d> points_;
  bool closed_ = false;
  std::vector<double> cumulative_cm_;  ///< arc length at each chord's end, from 0
};

/// The 3DTK frame's axes in the right-handed one (core/pose.hpp): v_3dtk = C v_rh.
Eigen::Matrix3d right_handed_to_3dtk_axes() {
  Eigen::Matrix3d c;
  for (int i = 0; i < 3; ++i) c.col(i) = right_handed_to_3dtk(Eigen::Vector3d::Unit(i), 1.0);
  return c;
}

void validate(const MovingSimulationSettings& s) {
  const auto fail = [](const std::string& what) { throw std::invalid_argument("moving survey settings: " + what); };
  if (!(s.rate_hz > 0.0) || !std::isfinite(s.rate_hz)) fail("rate_hz must be positive");
  if (!(s.range_noise_sigma_cm >= 0.0)) fail("range_noise_sigma_cm must not be negative");
  if (!(s.min_range_cm >= 0.0) || !(s.max_range_cm > s.min_range_cm)) fail("need 0 <= min_range_cm < max_range_cm");
  const double speed = s.effective_speed_mps();
  if (!(speed >= 0.0) || !std::isfinite(speed)) fail("speed_mps must be 0 or more");
  if (speed == 0.0 && s.sweeps <= 0) fail("a sensor standing still (speed 0) needs a number of sweeps");
  if (s.sweeps < 0) fail("sweeps must not be negative");
  if (!std::isfinite(s.turn_deg_s) || !(s.turn_period_s > 0.0)) fail("turn_deg_s must be finite, turn_period_s positive");
  if (!(s.mine.mean_step_cm > 0.0)) fail("mine.mean_step_cm (the waypoint spacing) must be positive");
  if (s.sensor == MovingSensor::kSpinning) {
    const SpinningLidarSettings& l = s.spinning;
    if (l.beams < 1 || l.beams > 65535 || l.columns < 1) fail("spinning: beams in [1, 65535] and columns >= 1");
    if (!(l.max_elevation_deg >= l.min_elevation_deg) || l.min_elevation_deg < -90.0 || l.max_elevation_deg > 90.0) {
      fail("spinning: need -90 <= min_elevation_deg <= max_elevation_deg <= 90");
    }
  } else {
    const HandheldLidarSettings& h = s.handheld;
    if (!(h.points_per_second >= s.rate_hz) || !(h.fov_deg > 0.0) || !(h.fov_deg < 180.0)) {
      fail("handheld: points_per_second >= rate_hz and fov_deg in (0, 180) required");
    }
    if (!(h.stride_cm > 0.0)) fail("handheld: stride_cm must be positive");
  }
}

}  // namespace

double MovingSimulationSettings::effective_speed_mps() const {
  if (speed_mps) return *speed_mps;
  return sensor == MovingSensor::kSpinning ? spinning.speed_mps : handheld.speed_mps;
}

// --- the trajectory --------------------------------------------------------------------------------

struct SensorTrajectory::Impl {
  Impl(std::shared_ptr<const MineWorld> world_in, WaypointPath path_in, double speed_cm_s_in)
      : world(std::move(world_in)), path(std::move(path_in)), speed_cm_s(speed_cm_s_in) {}

  std::shared_ptr<const MineWorld> world;
  WaypointPath path;
  double speed_cm_s = 0.0;
  double height_cm = 0.0;  ///< sensor above the floor (mount or carry height)
  double turn_amplitude_deg = 0.0;
  double turn_angular_rate = 0.0;  ///< rad/s of the weave's phase
  bool sway = false;
  HandheldLidarSettings handheld;
  double sway_phase[4] = {0.0, 0.0, 0.0, 0.0};  ///< roll, yaw, pitch, bob

  double distance_cm(double t_s) const { return std::clamp(speed_cm_s * t_s, 0.0, path.length_cm()); }

  Pose right_handed(double t_s) const {
    const double s = distance_cm(t_s);
    Eigen::Vector2d position, tangent;
    path.at(s, &position, &tangent);
    // 3DTK's heading theta_y: positive turns +z towards +x (trajectory.hpp).
    double heading_deg = std::atan2(tangent.x(), tangent.y()) / kRadPerDeg;
    if (turn_amplitude_deg != 0.0) heading_deg += turn_amplitude_deg * std::sin(turn_angular_rate * t_s);
    const Pose body_3dtk = robot_pose_on_floor(*world, {position.x(), position.y(), heading_deg}, height_cm);
    Pose pose = threedtk_pose_to_right_handed(body_3dtk, 1.0);
    if (sway) {
      // The walker's gait as a function of the distance walked: standing still, it stands still.
      const double stride = 2.0 * std::numbers::pi * s / handheld.stride_cm;
      const double roll = handheld.sway_roll_deg * kRadPerDeg * std::sin(stride + sway_phase[0]);
      const double yaw = handheld.sway_yaw_deg * kRadPerDeg * std::sin(stride + sway_phase[1]);
      const double pitch = handheld.sway_pitch_deg * kRadPerDeg * std::sin(2.0 * stride + sway_phase[2]);
      const double bob = handheld.bob_cm * std::sin(2.0 * stride + sway_phase[3]);
      Pose sway_pose = Pose::Identity();
      sway_pose.block<3, 3>(0, 0) = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                                     Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                                     Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                                        .toRotationMatrix();
      sway_pose(2, 3) = bob;
      pose = pose * sway_pose;
    }
    return pose;
  }
};

Pose SensorTrajectory::T_world_sensor(double t_s) const { return impl_->right_handed(t_s); }
Pose SensorTrajectory::T_world_sensor_3dtk(double t_s) const {
  return right_handed_pose_to_3dtk(impl_->right_handed(t_s), 1.0);
}
double SensorTrajectory::distance_cm(double t_s) const { return impl_->distance_cm(t_s); }
double SensorTrajectory::path_length_cm() const { return impl_->path.length_cm(); }
double SensorTrajectory::duration_s() const {
  return impl_->speed_cm_s > 0.0 ? impl_->path.length_cm() / impl_->speed_cm_s : std::numeric_limits<double>::infinity();
}
const MineWorld& SensorTrajectory::world() const { return *impl_->world; }

// --- the sensors -------------------------------------------------------------------------------------

namespace {

/// One return, in its slot of the sweep (absent: valid == false).
struct Return {
  Eigen::Vector3f point_cm = Eigen::Vector3f::Zero();
  float intensity = 0.0f;
  double time_s = 0.0;
  std::uint16_t ring = 0;
  bool valid = false;
};

/// How a sweep is laid out: `samples` firings at their own times, `rays` beams each.
/// Thread-safety: immutable; const members are pure.
class SweepModel {
 public:
  SweepModel(const MovingSimulationSettings& settings) : settings_(settings), period_s_(settings.sweep_period_s()) {
    if (settings.sensor == MovingSensor::kSpinning) {
      const SpinningLidarSettings& l = settings.spinning;
      samples_ = l.columns;
      rays_ = l.beams;
      for (int b = 0; b < l.beams; ++b) {
        const double el = (l.beams == 1 ? l.min_elevation_deg
                                        : l.min_elevation_deg + (l.max_elevation_deg - l.min_elevation_deg) * b / (l.beams - 1)) *
                          kRadPerDeg;
        elevation_cos_.push_back(std::cos(el));
        elevation_sin_.push_back(std::sin(el));
      }
      for (int c = 0; c < l.columns; ++c) {
        // Clockwise from behind (azimuth pi) through ahead (0, the middle column) to behind again.
        const double az = std::numbers::pi - 2.0 * std::numbers::pi * c / l.columns;
        azimuth_cos_.push_back(std::cos(az));
        azimuth_sin_.push_back(std::sin(az));
      }
    } else {
      samples_ = std::max(1, static_cast<int>(std::lround(settings.handheld.points_per_second / settings.rate_hz)));
      rays_ = 1;
    }
  }

  int samples() const { return samples_; }
  int rays() const { return rays_; }
  /// Sample i's time relative to its sweep's stamp: in [-T/2, T/2).
  double offset_s(int sample) const { return period_s_ * (static_cast<double>(sample) / samples_ - 0.5); }

  /// Unit direction of ray `ray` of sample `sample` (absolute time t_s), sensor frame.
  Eigen::Vector3d direction(int sample, int ray, double t_s) const {
    if (settings_.sensor == MovingSensor::kSpinning) {
      const auto c = static_cast<std::size_t>(sample), b = static_cast<std::size_t>(ray);
      return {elevation_cos_[b] * azimuth_cos_[c], elevation_cos_[b] * azimuth_sin_[c], elevation_sin_[b]};
    }
    // Two counter-rotating prisms, each deflecting by a quarter of the field of view: their sum
    // traces a rosette through the centre, out to half the field of view.
    const HandheldLidarSettings& h = settings_.handheld;
    const double half = 0.25 * h.fov_deg * kRadPerDeg;
    const double a = 2.0 * std::numbers::pi * h.prism_a_hz * t_s;
    const double b = 2.0 * std::numbers::pi * h.prism_b_hz * t_s;
    const double u = half * (std::cos(a) + std::cos(b));
    const double v = half * (std::sin(a) - std::sin(b));
    const double theta = std::hypot(u, v);  // off the x axis
    if (theta == 0.0) return Eigen::Vector3d::UnitX();
    const double s = std::sin(theta) / theta;
    return {std::cos(theta), s * u, s * v};
  }

 private:
  const MovingSimulationSettings& settings_;
  double period_s_;
  int samples_ = 0;
  int rays_ = 0;
  std::vector<double> elevation_cos_, elevation_sin_, azimuth_cos_, azimuth_sin_;
};

double reflectivity(SurfaceKind kind) {
  switch (kind) {
    case SurfaceKind::kFloor: return kFloorReflectivity;
    case SurfaceKind::kRoof: return kRoofReflectivity;
    case SurfaceKind::kRib: return kRibReflectivity;
    default: return kObjectReflectivity;
  }
}

/// |cos| of the angle between the ray (3DTK frame) and the surface's normal where it hit.
double incidence_cos(const MineWorld& world, SurfaceKind kind, const Eigen::Vector3d& hit_cm, const Eigen::Vector3d& d) {
  if (kind != SurfaceKind::kFloor && kind != SurfaceKind::kRoof) return kUnknownIncidenceCos;
  const FieldSample h = kind == SurfaceKind::kFloor ? world.floor_height(hit_cm.x(), hit_cm.z())
                                                    : world.roof_height(hit_cm.x(), hit_cm.z());
  const Eigen::Vector3d normal = Eigen::Vector3d(-h.d_du, 1.0, -h.d_dv).normalized();  // y = h(x, z)
  return std::abs(normal.dot(d));
}

/// Fills slots [first, last) of one sweep's samples (each sample's `rays` slots).
void measure(const SweepModel& model, const MovingSimulationSettings& settings, const SensorTrajectory::Impl& trajectory,
             const Eigen::Matrix3d& to_3dtk, std::size_t sweep, double stamp_s, int first, int last, Return* slots) {
  const MineWorld& world = *trajectory.world;
  for (int sample = first; sample < last; ++sample) {
    const double t = stamp_s + model.offset_s(sample);
    const Pose pose = trajectory.right_handed(t);
    const Eigen::Matrix3d rotation_3dtk = to_3dtk * pose.block<3, 3>(0, 0);
    const ViewPoint view = world.view_point(to_3dtk * pose.block<3, 1>(0, 3));
    for (int ray = 0; ray < model.rays(); ++ray) {
      const Eigen::Vector3d direction = model.direction(sample, ray, t);
      const Eigen::Vector3d d_3dtk = rotation_3dtk * direction;
      const RayHit hit = world.cast_ray(view, d_3dtk, settings.max_range_cm);
      if (!hit.hit()) continue;
      // A fixed number of draws per ray, in a fixed order, from the ray's own stream.
      CounterRng rng(key_for(settings.mine.seed, Stream::kBeam, kMovingBeamId, sweep, static_cast<std::uint64_t>(sample),
                             static_cast<std::uint64_t>(ray)));
      const double noise = rng.normal();
      const double speckle = rng.uniform(-kSpeckle, kSpeckle);
      const double range = hit.range_cm + settings.range_noise_sigma_cm * noise;
      if (range < settings.min_range_cm || range > settings.max_range_cm) continue;
      const Eigen::Vector3d hit_3dtk = view.origin_cm + hit.range_cm * d_3dtk;
      const double cos_incidence = incidence_cos(world, hit.kind, hit_3dtk, d_3dtk);
      Return& out = slots[static_cast<std::size_t>(sample) * static_cast<std::size_t>(model.rays()) +
                          static_cast<std::size_t>(ray)];
      out.point_cm = (direction * range).cast<float>();
      out.intensity = static_cast<float>(kIntensityScale * reflectivity(hit.kind) * (0.3 + 0.7 * cos_incidence) *
                                         std::exp(-range / kIntensityFalloffCm) * (1.0 + speckle));
      out.time_s = t;
      out.ring = static_cast<std::uint16_t>(ray);
      out.valid = true;
    }
  }
}

/// The stop-and-go error model scaled from its reference step to `step_cm` (MovingSimulationSettings::odometry).
OdometrySettings scaled_odometry(OdometrySettings errors, double step_cm) {
  const double ratio = step_cm / MineSettings{}.mean_step_cm;
  const double root = std::sqrt(ratio);
  errors.yaw_bias_deg_per_step *= ratio;
  errors.yaw_sigma_deg *= root;
  errors.pitch_roll_sigma_deg *= root;
  errors.lateral_sigma_cm *= root;
  errors.vertical_sigma_cm *= root;
  // A relative error per step: its absolute size grows with the square root of the distance too.
  errors.distance_sigma = ratio > 0.0 ? errors.distance_sigma / root : 0.0;
  return errors;
}

}  // namespace

MovingSurvey simulate_moving_survey(const MovingSimulationSettings& settings) {
  validate(settings);
  const double speed_mps = settings.effective_speed_mps();
  const double period_s = settings.sweep_period_s();

  // The waypoints: the stop-and-go survey's stops, evenly spaced (no jitter) on the same path.
  MineSettings waypoints = settings.mine;
  waypoints.step_jitter = 0.0;
  waypoints.heading_sigma_deg = 0.0;
  const bool loop = settings.mine.loop_length_cm > 0.0;
  std::shared_ptr<const MineWorld> world;
  std::vector<ScanStop> stops;
  if (loop) {
    world = std::make_shared<const MineWorld>(settings.mine, settings.mine.drive_length_cm);
    waypoints.scans = 0;
    stops = plan_loop_stops(waypoints, *world);
  } else {
    // Always explicit counts (plan_stops then keeps mean_step_cm), so a short drive's waypoints are
    // the start of a long one's; enough of them for the sweeps asked for, one spare past the end.
    const double needed_cm = kCmPerM * speed_mps * settings.sweeps * period_s;
    const double reach_cm = std::max(settings.mine.drive_length_cm, needed_cm);
    waypoints.scans = static_cast<int>(std::ceil(reach_cm / settings.mine.mean_step_cm)) + 2;
    stops = plan_stops(waypoints);
    world = std::make_shared<const MineWorld>(settings.mine, stops.back().z_cm);
  }
  std::vector<Eigen::Vector2d> points;
  points.reserve(stops.size());
  for (const ScanStop& stop : stops) points.emplace_back(stop.x_cm, stop.z_cm);

  auto impl = std::make_shared<SensorTrajectory::Impl>(world, WaypointPath(std::move(points), loop), kCmPerM * speed_mps);
  const bool handheld = settings.sensor == MovingSensor::kHandheld;
  impl->height_cm = handheld ? settings.handheld.carry_height_cm : settings.spinning.mount_height_cm;
  impl->turn_angular_rate = 2.0 * std::numbers::pi / settings.turn_period_s;
  impl->turn_amplitude_deg = settings.turn_deg_s / impl->turn_angular_rate;  // peak rate turn_deg_s
  impl->sway = handheld;
  impl->handheld = settings.handheld;
  if (handheld) {
    CounterRng rng(key_for(settings.mine.seed, Stream::kDrive, kSwayId));
    for (double& phase : impl->sway_phase) phase = rng.uniform(0.0, 2.0 * std::numbers::pi);
  }
  const SensorTrajectory trajectory(impl);

  // As many whole sweeps as the path holds (or as asked for; a loop holds one lap).
  std::size_t sweeps = static_cast<std::size_t>(std::max(0, settings.sweeps));
  if (speed_mps > 0.0) {
    const auto fit = static_cast<std::size_t>(std::floor(trajectory.duration_s() / period_s + 1e-9));
    sweeps = sweeps == 0 ? fit : std::min(sweeps, fit);
  }
  if (sweeps == 0) throw std::invalid_argument("moving survey: the path is too short for one sweep");

  MovingSurvey survey;
  survey.speed_mps = speed_mps;
  survey.trajectory = trajectory;
  survey.stamps_s.resize(sweeps);
  survey.truth_cm.resize(sweeps);
  for (std::size_t k = 0; k < sweeps; ++k) {
    survey.stamps_s[k] = (static_cast<double>(k) + 0.5) * period_s;
    survey.truth_cm[k] = trajectory.T_world_sensor(survey.stamps_s[k]);
  }
  survey.driven_distance_cm = trajectory.distance_cm(static_cast<double>(sweeps) * period_s) - trajectory.distance_cm(0.0);
  if (settings.odometry) {
    // The error model's axes are 3DTK's (lateral x, vertical y, yaw about y): drift there, then turn back.
    std::vector<Pose> truth_3dtk;
    truth_3dtk.reserve(sweeps);
    for (const Pose& pose : survey.truth_cm) truth_3dtk.push_back(right_handed_pose_to_3dtk(pose, 1.0));
    const std::vector<Pose> odometry_3dtk = simulate_odometry(
        truth_3dtk, scaled_odometry(settings.odometry_errors, kCmPerM * speed_mps * period_s), settings.mine.seed);
    for (const Pose& pose : odometry_3dtk) survey.odometry_cm.push_back(threedtk_pose_to_right_handed(pose, 1.0));
  }

  // Every sweep, and within it every block of samples, is an independent task writing its own
  // slots; randomness comes from per-ray counter streams: bit-identical for any threads or order.
  const SweepModel model(settings);
  const Eigen::Matrix3d to_3dtk = right_handed_to_3dtk_axes();
  const auto slots_per_sweep = static_cast<std::size_t>(model.samples()) * static_cast<std::size_t>(model.rays());
  survey.scans.resize(sweeps);
  tbb::parallel_for(std::size_t{0}, sweeps, [&](std::size_t sweep) {
    std::vector<Return> slots(slots_per_sweep);
    const double stamp = survey.stamps_s[sweep];
    const int tasks = (model.samples() + kSamplesPerTask - 1) / kSamplesPerTask;
    tbb::parallel_for(0, tasks, [&](int task) {
      const int first = task * kSamplesPerTask;
      measure(model, settings, *impl, to_3dtk, sweep, stamp, first, std::min(model.samples(), first + kSamplesPerTask),
              slots.data());
    });
    Scan& scan = survey.scans[sweep];
    char name[32];
    std::snprintf(name, sizeof(name), "scan%03zu", sweep);
    scan.name = name;
    scan.pose_cm = settings.odometry ? survey.odometry_cm[sweep] : Pose::Identity();
    const auto valid = static_cast<std::size_t>(
        std::count_if(slots.begin(), slots.end(), [](const Return& r) { return r.valid; }));
    scan.points_cm.reserve(valid);
    scan.attributes.time_s.reserve(valid);
    scan.attributes.intensity.reserve(valid);
    if (!handheld) scan.attributes.ring.reserve(valid);
    for (const Return& r : slots) {
      if (!r.valid) continue;
      scan.points_cm.push_back(r.point_cm);
      scan.attributes.time_s.push_back(r.time_s);
      scan.attributes.intensity.push_back(r.intensity);
      if (!handheld) scan.attributes.ring.push_back(r.ring);
    }
  });
  return survey;
}

}  // namespace minemap::sim
