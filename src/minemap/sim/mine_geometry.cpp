#include "minemap/sim/mine_geometry.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <optional>
#include <stdexcept>

#include "minemap/sim/sim_random.hpp"

namespace minemap::sim {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// --- extent of the workings ---
constexpr double kMineBehindStartCm = 2000.0;  ///< open entries behind scan 0 (the scanner looks ahead)
/// Open entries past the drive's end: beyond a SICK's 80 m, so the far face is rarely seen.
constexpr double kMineBeyondDriveCm = 9000.0;
constexpr double kRockThicknessCm = 2000.0;  ///< solid rock around the workings (never seen through)
constexpr double kGridCellCm = 200.0;        ///< x-z grid for ray traversal: about half an entry

// --- surfaces ---
constexpr double kMaxCrossSlope = 0.008;       ///< floor tilt across the drive (about 0.5 deg): roll
constexpr double kUndulationMajorCm = 35.0;    ///< the seam's long rolls along the drive: pitch
constexpr int kUndulationMajorHalfWaves = 3;   ///< over the drive length (zero at both ends)
constexpr double kUndulationMinorCm = 12.0;
constexpr int kUndulationMinorHalfWaves = 11;
constexpr NoiseOctave kSeamRoll{2500.0, 12.0};      ///< 2D rolls both floor and roof follow
constexpr NoiseOctave kSeamThickness{3000.0, 18.0};  ///< roof height varies +-18 cm around the mean
/// Roughness octaves relative to the largest (3 m): 0.3-3 m wavelengths, amplitudes falling off.
constexpr std::array<double, 3> kRoughWavelengthsCm = {300.0, 100.0, 33.0};
constexpr std::array<double, 3> kRoughRelativeAmplitude = {1.0, 0.45, 0.2};

// --- pillars ---
constexpr double kPillarRibJitterCm = 25.0;  ///< pillar ribs are not cut on a perfect line

// --- timber sets (roof bar on two posts) ---
constexpr double kBarDepthCm = 20.0;       ///< vertical size of a roof bar
constexpr double kBarThicknessCm = 20.0;   ///< along the drive
constexpr double kBarIntoRibCm = 30.0;     ///< bars are let into the ribs
constexpr double kPostHalfCm = 10.0;
constexpr double kPostMaxGapCm = 8.0;      ///< posts stand up to this far off the rib
constexpr double kSolidEmbedCm = 5.0;      ///< solids reach this far into floor / roof
constexpr double kSetClearOfBrokenBarCm = 250.0;

// --- rails ---
constexpr double kRailHalfGaugeCm = 55.0;
constexpr double kRailHalfWidthCm = 3.5;
constexpr double kRailHalfHeightCm = 5.0;
constexpr double kRailSegmentCm = 500.0;  ///< rails follow the floor piecewise
constexpr double kRailSunkCm = 1.0;       ///< rails sit this deep in the (smooth) floor

// --- rubble ---
constexpr double kDriveClearanceCm = 120.0;  ///< the robot's lane: no rubble within this of x = 0
constexpr double kPileRadiusCm = 80.0;
constexpr int kPileMinPieces = 2;
constexpr int kPileMaxPieces = 6;
constexpr double kRubbleMinHalfCm = 8.0;
constexpr double kRubbleMaxHalfCm = 30.0;
constexpr double kRubbleMinHalfHeightCm = 5.0;
constexpr double kRubbleMaxHalfHeightCm = 18.0;
constexpr double kEntryWallMarginCm = 60.0;  ///< parallel-entry rubble keeps off the ribs
constexpr double kDrivePileRibMarginCm = 20.0;  ///< pile centres in the drive stay this far off the rib
constexpr double kRubbleBuriedMin = 0.2;     ///< share of a piece's height sunk into the floor
constexpr double kRubbleBuriedMax = 0.5;

// --- the broken roof bar ---
constexpr double kBrokenBarAheadCm = 350.0;  ///< past the last scan pose: the robot turned back here
constexpr double kBrokenBarHalfCm = 10.0;
/// Where the broken bar's ends are, relative to its z and the drive's ribs: the upper end still
/// let into one rib's roof corner, the lower end on the floor near the other rib, further on.
constexpr double kBrokenBarTopRibOffsetCm = 40.0;
constexpr double kBrokenBarBottomRibOffsetCm = 80.0;
constexpr double kBrokenBarTopBackCm = 60.0;
constexpr double kBrokenBarBottomAheadCm = 140.0;

// --- root finding onto rough surfaces ---
constexpr double kRootToleranceCm = 0.01;  ///< |normal offset| accepted as on the surface
constexpr double kRootBracketCm = 1e-4;
constexpr int kMaxRootIterations = 60;
constexpr double kMinHitCm = 1e-6;

constexpr std::uint32_t kBoxFlag = 0x80000000u;

/// Finds a root of g in [lo, hi] with g(lo) > 0 (open space): safeguarded Newton, bisection when a
/// step leaves the bracket. If g(hi) is not known to be <= 0 it is evaluated first; no crossing
/// there means no hit. `eval(t, &dg)` returns g(t) and its derivative.
template <typename Eval>
std::optional<double> solve_crossing(const Eval& eval, double lo, double hi, bool hi_known_below, double guess) {
  if (!(lo < hi)) return std::nullopt;
  if (!hi_known_below) {
    double dg = 0.0;
    const double g_hi = eval(hi, &dg);
    if (g_hi > 0.0) return std::nullopt;
    if (g_hi > -kRootToleranceCm) return hi;
  }
  double t = std::isfinite(guess) ? std::clamp(guess, lo, hi) : 0.5 * (lo + hi);
  for (int iteration = 0; iteration < kMaxRootIterations; ++iteration) {
    double dg = 0.0;
    const double g = eval(t, &dg);
    if (std::abs(g) <= kRootToleranceCm) return t;
    if (g > 0.0) {
      lo = t;
    } else {
      hi = t;
    }
    if (hi - lo <= kRootBracketCm) return 0.5 * (lo + hi);
    double next = dg != 0.0 ? t - g / dg : kNaN;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    t = next;
  }
  return t;
}

/// Slab interval of the ray o + t d against [lo, hi] along one axis.
inline bool slab(double o, double d, double lo, double hi, double& t_near, double& t_far) {
  if (d == 0.0) {
    if (o < lo || o > hi) return false;
    t_near = -kInf;
    t_far = kInf;
    return true;
  }
  const double inv = 1.0 / d;
  double a = (lo - o) * inv;
  double b = (hi - o) * inv;
  if (a > b) std::swap(a, b);
  t_near = a;
  t_far = b;
  return true;
}

Eigen::Matrix3d yaw_axes(double yaw_rad) {
  // 3DTK's Ry: rotates z towards +x.
  const double c = std::cos(yaw_rad);
  const double s = std::sin(yaw_rad);
  Eigen::Matrix3d r;
  r << c, 0, s, 0, 1, 0, -s, 0, c;
  return r;
}

/// Axes with the first along `along` and the second as close to world up as possible.
Eigen::Matrix3d axes_along(const Eigen::Vector3d& along) {
  const Eigen::Vector3d x = along.normalized();
  Eigen::Vector3d y = Eigen::Vector3d::UnitY() - Eigen::Vector3d::UnitY().dot(x) * x;
  if (y.norm() < 1e-9) y = Eigen::Vector3d::UnitX();
  y.normalize();
  Eigen::Matrix3d r;
  r.col(0) = x;
  r.col(1) = y;
  r.col(2) = x.cross(y);
  return r;
}

std::vector<NoiseOctave> rough_octaves(double amplitude_cm) {
  std::vector<NoiseOctave> octaves;
  for (std::size_t i = 0; i < kRoughWavelengthsCm.size(); ++i) {
    octaves.push_back({kRoughWavelengthsCm[i], amplitude_cm * kRoughRelativeAmplitude[i]});
  }
  return octaves;
}

}  // namespace

MineWorld::MineWorld(const MineSettings& settings, double drive_end_z_cm) {
  if (!(settings.drive_length_cm > 0.0) || !(settings.main_entry_width_cm > 0.0) ||
      !(settings.entry_height_cm > 0.0) || settings.parallel_entries_per_side < 0 ||
      !(settings.crosscut_spacing_min_cm > settings.crosscut_width_max_cm) ||
      !(settings.timber_set_spacing_min_cm > 0.0) || !(settings.rubble_pile_spacing_min_cm > 0.0) ||
      !(settings.pillar_width_min_cm > 2.0 * kPillarRibJitterCm)) {
    throw std::invalid_argument("mine settings: sizes must be positive, cross-cuts narrower than their spacing");
  }
  // Surfaces: one stream for all of them, drawn in a fixed order.
  CounterRng rng(key_for(settings.seed, Stream::kSurfaces));
  slope_ = settings.elevation_gain_cm / settings.drive_length_cm;
  cross_slope_ = rng.uniform(-kMaxCrossSlope, kMaxCrossSlope);
  // Rolls along the drive that vanish at both its ends, so the gain over the drive is exact.
  undulation_amp_cm_[0] = rng.sign() * kUndulationMajorCm;
  undulation_amp_cm_[1] = rng.sign() * kUndulationMinorCm;
  undulation_wavenumber_[0] = kUndulationMajorHalfWaves * std::numbers::pi / settings.drive_length_cm;
  undulation_wavenumber_[1] = kUndulationMinorHalfWaves * std::numbers::pi / settings.drive_length_cm;
  undulation_bound_cm_ = kUndulationMajorCm + kUndulationMinorCm;
  seam_height_cm_ = settings.entry_height_cm;
  const std::array<NoiseOctave, 1> roll{kSeamRoll};
  const std::array<NoiseOctave, 1> thickness{kSeamThickness};
  seam_roll_ = RoughnessField(rng.next_bits(), roll);
  seam_height_ = RoughnessField(rng.next_bits(), thickness);
  floor_rough_ = RoughnessField(rng.next_bits(), rough_octaves(settings.floor_roughness_cm));
  roof_rough_ = RoughnessField(rng.next_bits(), rough_octaves(settings.ceiling_roughness_cm));
  rib_x_rough_ = RoughnessField(rng.next_bits(), rough_octaves(settings.wall_roughness_cm));
  rib_z_rough_ = RoughnessField(rng.next_bits(), rough_octaves(settings.wall_roughness_cm));
  floor_band_cm_ = undulation_bound_cm_ + seam_roll_.bound_cm() + floor_rough_.bound_cm();
  roof_band_cm_ = undulation_bound_cm_ + seam_roll_.bound_cm() + seam_height_.bound_cm() + roof_rough_.bound_cm();
  rib_band_cm_ = rib_x_rough_.bound_cm();
  floor_smooth_slope_ = std::abs(undulation_amp_cm_[0]) * undulation_wavenumber_[0] +
                        std::abs(undulation_amp_cm_[1]) * undulation_wavenumber_[1] + seam_roll_.slope_bound();
  roof_smooth_slope_ = floor_smooth_slope_ + seam_height_.slope_bound();

  build_layout(settings, drive_end_z_cm);
  build_grid();
}

// ------------------------------------------------------------------------------------------------
// Surfaces

double MineWorld::undulation(double z_cm, double* d_dz) const {
  double value = 0.0;
  double derivative = 0.0;
  for (int i = 0; i < 2; ++i) {
    const double phase = undulation_wavenumber_[i] * z_cm;
    value += undulation_amp_cm_[i] * std::sin(phase);
    derivative += undulation_amp_cm_[i] * undulation_wavenumber_[i] * std::cos(phase);
  }
  if (d_dz != nullptr) *d_dz = derivative;
  return value;
}

double MineWorld::smooth_floor_cm(double x_cm, double z_cm) const {
  return floor_plane(x_cm, z_cm) + undulation(z_cm, nullptr) + seam_roll_.value(x_cm, z_cm);
}

double MineWorld::smooth_roof_cm(double x_cm, double z_cm) const {
  return smooth_floor_cm(x_cm, z_cm) + seam_height_cm_ + seam_height_.value(x_cm, z_cm);
}

FieldSample MineWorld::floor_height(double x_cm, double z_cm) const {
  double d_undulation = 0.0;
  const double u = undulation(z_cm, &d_undulation);
  const FieldSample roll = seam_roll_.sample(x_cm, z_cm);
  const FieldSample rough = floor_rough_.sample(x_cm, z_cm);
  FieldSample s;
  s.value = floor_plane(x_cm, z_cm) + u + roll.value + rough.value;
  s.d_du = cross_slope_ + roll.d_du + rough.d_du;
  s.d_dv = slope_ + d_undulation + roll.d_dv + rough.d_dv;
  return s;
}

FieldSample MineWorld::roof_height(double x_cm, double z_cm) const {
  double d_undulation = 0.0;
  const double u = undulation(z_cm, &d_undulation);
  const FieldSample roll = seam_roll_.sample(x_cm, z_cm);
  const FieldSample thickness = seam_height_.sample(x_cm, z_cm);
  const FieldSample rough = roof_rough_.sample(x_cm, z_cm);
  FieldSample s;
  s.value = floor_plane(x_cm, z_cm) + u + roll.value + seam_height_cm_ + thickness.value + rough.value;
  s.d_du = cross_slope_ + roll.d_du + thickness.d_du + rough.d_du;
  s.d_dv = slope_ + d_undulation + roll.d_dv + thickness.d_dv + rough.d_dv;
  return s;
}

// ------------------------------------------------------------------------------------------------
// Layout

double MineWorld::drive_rib_x(int side, double z_cm, double clearance_cm) const {
  const int row = drive_row_[side > 0 ? 1 : 0];
  if (row < 0) return side > 0 ? rock_x_cm_[1] : rock_x_cm_[0];
  for (const int index : rows_[row].pillars) {
    const RockPrism& p = prisms_[index];
    if (p.z_min_cm <= z_cm - clearance_cm && p.z_max_cm >= z_cm + clearance_cm) {
      return side > 0 ? p.x_min_cm : p.x_max_cm;
    }
  }
  return kNaN;
}

std::vector<double> MineWorld::drive_crosscuts_z(int side) const {
  const int row = drive_row_[side > 0 ? 1 : 0];
  std::vector<double> centres;
  if (row < 0) return centres;
  const std::vector<int>& pillars = rows_[static_cast<std::size_t>(row)].pillars;
  for (std::size_t k = 1; k < pillars.size(); ++k) {
    centres.push_back(0.5 * (prisms_[static_cast<std::size_t>(pillars[k - 1])].z_max_cm +
                             prisms_[static_cast<std::size_t>(pillars[k])].z_min_cm));
  }
  return centres;
}

void MineWorld::build_layout(const MineSettings& settings, double drive_end_z_cm) {
  const double mine_drive_end = std::max(settings.drive_length_cm, drive_end_z_cm);
  z_start_cm_ = -kMineBehindStartCm;
  z_end_cm_ = mine_drive_end + kMineBeyondDriveCm;
  const double half_width = 0.5 * settings.main_entry_width_cm;

  // Entries and pillar rows, outwards from the drive: right side (+x) first, then left.
  CounterRng layout(key_for(settings.seed, Stream::kLayout));
  entries_.push_back({-half_width, half_width});
  struct RowSpan {
    int side;
    double x_min;
    double x_max;
  };
  std::vector<RowSpan> row_spans;
  for (const int side : {+1, -1}) {
    double edge = half_width;  // distance of the current rib from x = 0
    for (int e = 0; e < settings.parallel_entries_per_side; ++e) {
      const double pillar_width = layout.uniform(settings.pillar_width_min_cm, settings.pillar_width_max_cm);
      const double entry_width =
          layout.uniform(settings.parallel_entry_width_min_cm, settings.parallel_entry_width_max_cm);
      if (side > 0) {
        row_spans.push_back({side, edge, edge + pillar_width});
        entries_.push_back({edge + pillar_width, edge + pillar_width + entry_width});
      } else {
        row_spans.push_back({side, -edge - pillar_width, -edge});
        entries_.push_back({-edge - pillar_width - entry_width, -edge - pillar_width});
      }
      edge += pillar_width + entry_width;
    }
    rock_x_cm_[side > 0 ? 1 : 0] = side * edge;
  }

  // Pillars: each row has its own irregular cross-cut sequence, so the drive's two ribs open at
  // unrelated places and no stretch of the mine repeats another.
  for (std::size_t r = 0; r < row_spans.size(); ++r) {
    const RowSpan& span = row_spans[r];
    CounterRng row_rng(key_for(settings.seed, Stream::kPillarRow, r));
    PillarRow row;
    row.side = span.side;
    double pillar_start = z_start_cm_ - kRockThicknessCm;
    double crosscut_centre = z_start_cm_ + row_rng.uniform(0.0, settings.crosscut_spacing_max_cm);
    while (pillar_start < z_end_cm_) {
      const double width = row_rng.uniform(settings.crosscut_width_min_cm, settings.crosscut_width_max_cm);
      double pillar_end = crosscut_centre - 0.5 * width;
      if (pillar_end > z_end_cm_) pillar_end = z_end_cm_ + kRockThicknessCm;
      RockPrism pillar;
      pillar.x_min_cm = span.x_min + row_rng.uniform(-kPillarRibJitterCm, kPillarRibJitterCm);
      pillar.x_max_cm = span.x_max + row_rng.uniform(-kPillarRibJitterCm, kPillarRibJitterCm);
      pillar.z_min_cm = pillar_start;
      pillar.z_max_cm = pillar_end;
      row.pillars.push_back(static_cast<int>(prisms_.size()));
      prisms_.push_back(pillar);
      pillar_start = crosscut_centre + 0.5 * width;
      crosscut_centre += row_rng.uniform(settings.crosscut_spacing_min_cm, settings.crosscut_spacing_max_cm);
    }
    if (row_spans[r].side > 0 && drive_row_[1] < 0) drive_row_[1] = static_cast<int>(rows_.size());
    if (row_spans[r].side < 0 && drive_row_[0] < 0) drive_row_[0] = static_cast<int>(rows_.size());
    rows_.push_back(std::move(row));
  }

  // The solid rock around the workings.
  const double x_lo = rock_x_cm_[0];
  const double x_hi = rock_x_cm_[1];
  prisms_.push_back({x_lo - kRockThicknessCm, x_lo, z_start_cm_ - kRockThicknessCm, z_end_cm_ + kRockThicknessCm});
  prisms_.push_back({x_hi, x_hi + kRockThicknessCm, z_start_cm_ - kRockThicknessCm, z_end_cm_ + kRockThicknessCm});
  prisms_.push_back({x_lo - kRockThicknessCm, x_hi + kRockThicknessCm, z_start_cm_ - kRockThicknessCm, z_start_cm_});
  prisms_.push_back({x_lo - kRockThicknessCm, x_hi + kRockThicknessCm, z_end_cm_, z_end_cm_ + kRockThicknessCm});

  const double roof_margin = roof_rough_.bound_cm();
  const double floor_margin = floor_rough_.bound_cm();

  // The broken roof bar: across the drive, one end still up at the roof, the other on the floor.
  if (settings.broken_bar_at_end) {
    broken_bar_z_cm_ = mine_drive_end + kBrokenBarAheadCm;
    const double side = layout.sign();
    const double z = broken_bar_z_cm_;
    const double x_top = -side * (half_width - kBrokenBarTopRibOffsetCm);
    const double x_bottom = side * (half_width - kBrokenBarBottomRibOffsetCm);
    const double z_top = z - kBrokenBarTopBackCm;
    const double z_bottom = z + kBrokenBarBottomAheadCm;
    const Eigen::Vector3d top(x_top, smooth_roof_cm(x_top, z_top) - roof_margin - kBrokenBarHalfCm, z_top);
    const Eigen::Vector3d bottom(x_bottom, smooth_floor_cm(x_bottom, z_bottom) + kBrokenBarHalfCm, z_bottom);
    OrientedBox bar;
    bar.centre_cm = 0.5 * (top + bottom);
    bar.axes = axes_along(bottom - top);
    bar.half_extent_cm = Eigen::Vector3d(0.5 * (bottom - top).norm(), kBrokenBarHalfCm, kBrokenBarHalfCm);
    bar.kind = ObjectKind::kBrokenBar;
    boxes_.push_back(bar);
  }

  // Timber sets along the drive: a roof bar let into both ribs, on posts where a rib stands.
  CounterRng timber(key_for(settings.seed, Stream::kTimber));
  for (double z = z_start_cm_ + timber.uniform(0.0, settings.timber_set_spacing_max_cm); z < z_end_cm_;
       z += timber.uniform(settings.timber_set_spacing_min_cm, settings.timber_set_spacing_max_cm)) {
    const double post_gap_right = timber.uniform(0.0, kPostMaxGapCm);
    const double post_gap_left = timber.uniform(0.0, kPostMaxGapCm);
    if (std::abs(z - broken_bar_z_cm_) < kSetClearOfBrokenBarCm) continue;  // false when NaN
    double roof = kInf;
    for (const double x : {-half_width, 0.0, half_width}) roof = std::min(roof, smooth_roof_cm(x, z) - roof_margin);
    OrientedBox bar;
    bar.centre_cm = Eigen::Vector3d(0.0, roof - 0.5 * kBarDepthCm, z);
    bar.half_extent_cm = Eigen::Vector3d(half_width + kBarIntoRibCm, 0.5 * kBarDepthCm, 0.5 * kBarThicknessCm);
    bar.kind = ObjectKind::kRoofBar;
    boxes_.push_back(bar);
    const double bar_bottom = roof - kBarDepthCm;
    for (const int side : {+1, -1}) {
      const double rib = drive_rib_x(side, z, kPostHalfCm + kSolidEmbedCm);
      if (std::isnan(rib)) continue;  // a cross-cut opens here: the bar spans it unsupported
      const double gap = side > 0 ? post_gap_right : post_gap_left;
      const double x = rib - side * (kPostHalfCm + gap);
      const double bottom = smooth_floor_cm(x, z) - floor_margin - kSolidEmbedCm;
      OrientedBox post;
      post.centre_cm = Eigen::Vector3d(x, 0.5 * (bottom + bar_bottom), z);
      post.half_extent_cm = Eigen::Vector3d(kPostHalfCm, 0.5 * (bar_bottom - bottom), kPostHalfCm);
      post.kind = ObjectKind::kPost;
      boxes_.push_back(post);
    }
  }

  // A mine railway down the drive, laid piecewise on the floor.
  if (settings.rails) {
    for (const double x : {-kRailHalfGaugeCm, kRailHalfGaugeCm}) {
      for (double z0 = z_start_cm_; z0 < z_end_cm_; z0 += kRailSegmentCm) {
        const double z1 = std::min(z0 + kRailSegmentCm, z_end_cm_);
        const Eigen::Vector3d a(x, smooth_floor_cm(x, z0) + kRailHalfHeightCm - kRailSunkCm, z0);
        const Eigen::Vector3d b(x, smooth_floor_cm(x, z1) + kRailHalfHeightCm - kRailSunkCm, z1);
        OrientedBox rail;
        rail.centre_cm = 0.5 * (a + b);
        const Eigen::Matrix3d along = axes_along(b - a);  // col 0 along the rail, col 1 up
        rail.axes.col(0) = along.col(2);                  // across the rail (x, up to sign)
        rail.axes.col(1) = along.col(1);
        rail.axes.col(2) = along.col(0);
        if (rail.axes.determinant() < 0.0) rail.axes.col(0) = -rail.axes.col(0);
        rail.half_extent_cm = Eigen::Vector3d(kRailHalfWidthCm, kRailHalfHeightCm, 0.5 * (b - a).norm());
        rail.kind = ObjectKind::kRail;
        boxes_.push_back(rail);
      }
    }
  }

  // Rubble piles: along every entry, in the drive off the robot's lane.
  for (std::size_t e = 0; e < entries_.size(); ++e) {
    const EntrySpan entry = entries_[e];
    CounterRng rubble(key_for(settings.seed, Stream::kRubble, e));
    for (double z = z_start_cm_ + rubble.uniform(0.0, settings.rubble_pile_spacing_max_cm); z < z_end_cm_;
         z += rubble.uniform(settings.rubble_pile_spacing_min_cm, settings.rubble_pile_spacing_max_cm)) {
      const bool in_drive = e == 0;
      const double side = rubble.sign();
      const double x_centre = in_drive ? side * rubble.uniform(kDriveClearanceCm, half_width - kDrivePileRibMarginCm)
                                       : rubble.uniform(entry.x_min_cm + kEntryWallMarginCm,
                                                        entry.x_max_cm - kEntryWallMarginCm);
      const int pieces = rubble.uniform_int(kPileMinPieces, kPileMaxPieces);
      for (int k = 0; k < pieces; ++k) {
        OrientedBox piece;
        piece.half_extent_cm = Eigen::Vector3d(rubble.uniform(kRubbleMinHalfCm, kRubbleMaxHalfCm),
                                               rubble.uniform(kRubbleMinHalfHeightCm, kRubbleMaxHalfHeightCm),
                                               rubble.uniform(kRubbleMinHalfCm, kRubbleMaxHalfCm));
        piece.axes = yaw_axes(rubble.uniform(0.0, std::numbers::pi));
        double x = x_centre + rubble.uniform(-kPileRadiusCm, kPileRadiusCm);
        const double pz = z + rubble.uniform(-kPileRadiusCm, kPileRadiusCm);
        const double buried = rubble.uniform(kRubbleBuriedMin, kRubbleBuriedMax);
        const double reach = std::hypot(piece.half_extent_cm.x(), piece.half_extent_cm.z());
        if (in_drive && std::abs(x) - reach < kDriveClearanceCm) x = side * (kDriveClearanceCm + reach);
        const double lift = (1.0 - 2.0 * buried) * piece.half_extent_cm.y();  // centre above the floor
        piece.centre_cm = Eigen::Vector3d(x, smooth_floor_cm(x, pz) + lift, pz);
        piece.kind = ObjectKind::kRubble;
        boxes_.push_back(piece);
      }
    }
  }

  box_world_to_local_.reserve(boxes_.size());
  for (const OrientedBox& box : boxes_) box_world_to_local_.push_back(box.axes.transpose());
}

void MineWorld::build_grid() {
  grid_x0_cm_ = rock_x_cm_[0] - kGridCellCm;
  grid_z0_cm_ = z_start_cm_ - kGridCellCm;
  grid_nx_ = static_cast<int>(std::ceil((rock_x_cm_[1] - rock_x_cm_[0]) / kGridCellCm)) + 2;
  grid_nz_ = static_cast<int>(std::ceil((z_end_cm_ - z_start_cm_) / kGridCellCm)) + 2;
  const std::size_t cells = static_cast<std::size_t>(grid_nx_) * grid_nz_;

  // Footprints in cell indices, clipped to the grid.
  struct Footprint {
    int ix0, ix1, iz0, iz1;
    std::uint32_t item;
  };
  std::vector<Footprint> footprints;
  const auto add = [&](double x_min, double x_max, double z_min, double z_max, std::uint32_t item) {
    const auto cell_x = [&](double x) {
      return std::clamp(static_cast<int>(std::floor((x - grid_x0_cm_) / kGridCellCm)), 0, grid_nx_ - 1);
    };
    const auto cell_z = [&](double z) {
      return std::clamp(static_cast<int>(std::floor((z - grid_z0_cm_) / kGridCellCm)), 0, grid_nz_ - 1);
    };
    footprints.push_back({cell_x(x_min), cell_x(x_max), cell_z(z_min), cell_z(z_max), item});
  };
  for (std::size_t i = 0; i < prisms_.size(); ++i) {
    const RockPrism& p = prisms_[i];
    add(p.x_min_cm, p.x_max_cm, p.z_min_cm, p.z_max_cm, static_cast<std::uint32_t>(i));
  }
  for (std::size_t i = 0; i < boxes_.size(); ++i) {
    const OrientedBox& b = boxes_[i];
    // x-z reach of the box: sum over its axes of |axis| * half extent.
    const double reach_x = (b.axes.row(0).cwiseAbs().transpose().array() * b.half_extent_cm.array()).sum();
    const double reach_z = (b.axes.row(2).cwiseAbs().transpose().array() * b.half_extent_cm.array()).sum();
    add(b.centre_cm.x() - reach_x, b.centre_cm.x() + reach_x, b.centre_cm.z() - reach_z, b.centre_cm.z() + reach_z,
        static_cast<std::uint32_t>(i) | kBoxFlag);
  }
  std::vector<std::uint32_t> counts(cells + 1, 0);
  for (const Footprint& f : footprints) {
    for (int iz = f.iz0; iz <= f.iz1; ++iz) {
      for (int ix = f.ix0; ix <= f.ix1; ++ix) ++counts[static_cast<std::size_t>(iz) * grid_nx_ + ix + 1];
    }
  }
  for (std::size_t c = 0; c < cells; ++c) counts[c + 1] += counts[c];
  cell_start_ = counts;
  cell_items_.assign(cell_start_.back(), 0);
  std::vector<std::uint32_t> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (const Footprint& f : footprints) {
    for (int iz = f.iz0; iz <= f.iz1; ++iz) {
      for (int ix = f.ix0; ix <= f.ix1; ++ix) {
        cell_items_[fill[static_cast<std::size_t>(iz) * grid_nx_ + ix]++] = f.item;
      }
    }
  }
}

// ------------------------------------------------------------------------------------------------
// Queries

ViewPoint MineWorld::view_point(const Eigen::Vector3d& origin_cm) const {
  ViewPoint view;
  view.origin_cm = origin_cm;
  const double plane = floor_plane(origin_cm.x(), origin_cm.z());
  view.floor_offset_cm = smooth_floor_cm(origin_cm.x(), origin_cm.z()) - plane;
  view.roof_offset_cm = smooth_roof_cm(origin_cm.x(), origin_cm.z()) - plane;
  return view;
}

bool MineWorld::in_open_space(const Eigen::Vector3d& p) const {
  if (p.y() <= floor_height(p.x(), p.z()).value || p.y() >= roof_height(p.x(), p.z()).value) return false;
  const int ix = static_cast<int>(std::floor((p.x() - grid_x0_cm_) / kGridCellCm));
  const int iz = static_cast<int>(std::floor((p.z() - grid_z0_cm_) / kGridCellCm));
  if (ix < 0 || iz < 0 || ix >= grid_nx_ || iz >= grid_nz_) return false;
  const std::size_t cell = static_cast<std::size_t>(iz) * grid_nx_ + ix;
  for (std::uint32_t k = cell_start_[cell]; k < cell_start_[cell + 1]; ++k) {
    const std::uint32_t item = cell_items_[k];
    if ((item & kBoxFlag) != 0) {
      const std::uint32_t b = item & ~kBoxFlag;
      const Eigen::Vector3d local = box_world_to_local_[b] * (p - boxes_[b].centre_cm);
      if ((local.cwiseAbs().array() <= boxes_[b].half_extent_cm.array()).all()) return false;
    } else {
      const RockPrism& r = prisms_[item];
      if (p.x() >= r.x_min_cm && p.x() <= r.x_max_cm && p.z() >= r.z_min_cm && p.z() <= r.z_max_cm) return false;
    }
  }
  return true;
}

RayHit MineWorld::cast_ray(const ViewPoint& view, const Eigen::Vector3d& d, double max_range_cm) const {
  const Eigen::Vector3d& o = view.origin_cm;
  RayHit result;

  // Height of the ray above the reference plane: q(t) = q0 + t * q1. Two bounds bracket the floor
  // and roof crossings analytically:
  //  - bands: the floor lies within +-floor_band of the plane, the roof within +-roof_band of
  //    plane + seam height;
  //  - slopes: near the viewpoint, the smooth floor (roof) departs from its offset at the origin by
  //    at most slope bound * horizontal distance, plus the roughness bound.
  const double q0 = o.y() - floor_plane(o.x(), o.z());
  const double q1 = d.y() - slope_ * d.z() - cross_slope_ * d.x();
  const double horizontal = std::hypot(d.x(), d.z());
  double floor_lo = 0.0, floor_hi = kInf, floor_guess = kNaN;
  bool floor_hi_below = false;
  if (q1 < 0.0) {
    floor_lo = std::max(0.0, (floor_band_cm_ - q0) / q1);
    floor_hi = (-floor_band_cm_ - q0) / q1;
    floor_hi_below = true;
    floor_guess = (view.floor_offset_cm - q0) / q1;
  } else if (q0 > floor_band_cm_) {
    floor_lo = kInf;
  }
  {
    const double clearance = q0 - view.floor_offset_cm - floor_rough_.bound_cm();  // > 0: above any floor here
    const double closing = floor_smooth_slope_ * horizontal - q1;  // fastest approach per unit t
    if (clearance > 0.0) floor_lo = std::max(floor_lo, closing > 0.0 ? clearance / closing : kInf);
    const double receding = q1 + floor_smooth_slope_ * horizontal;  // slowest approach per unit t
    if (receding < 0.0) {
      const double below = (q0 - view.floor_offset_cm + floor_rough_.bound_cm()) / -receding;
      if (below < floor_hi) {
        floor_hi = below;
        floor_hi_below = true;
      }
    }
  }
  const double r0 = q0 - seam_height_cm_;
  double roof_lo = 0.0, roof_hi = kInf, roof_guess = kNaN;
  bool roof_hi_above = false;
  if (q1 > 0.0) {
    roof_lo = std::max(0.0, (-roof_band_cm_ - r0) / q1);
    roof_hi = (roof_band_cm_ - r0) / q1;
    roof_hi_above = true;
    roof_guess = (view.roof_offset_cm - seam_height_cm_ - r0) / q1;
  } else if (r0 < -roof_band_cm_) {
    roof_lo = kInf;
  }
  {
    const double clearance = view.roof_offset_cm - roof_rough_.bound_cm() - q0;  // > 0: below any roof here
    const double closing = q1 + roof_smooth_slope_ * horizontal;
    if (clearance > 0.0) roof_lo = std::max(roof_lo, closing > 0.0 ? clearance / closing : kInf);
    const double receding = q1 - roof_smooth_slope_ * horizontal;
    if (receding > 0.0) {
      const double above = (view.roof_offset_cm + roof_rough_.bound_cm() - q0) / receding;
      if (above < roof_hi) {
        roof_hi = above;
        roof_hi_above = true;
      }
    }
  }
  const double t_limit = std::min({max_range_cm, floor_hi_below ? floor_hi : kInf, roof_hi_above ? roof_hi : kInf});

  // --- solids: 2D DDA over the x-z grid ---
  double best_t = kInf;
  std::uint32_t best_item = 0;
  int best_axis = 0;  // prisms: 0 = x face, 2 = z face
  double best_sign = 0.0;
  int ix = static_cast<int>(std::floor((o.x() - grid_x0_cm_) / kGridCellCm));
  int iz = static_cast<int>(std::floor((o.z() - grid_z0_cm_) / kGridCellCm));
  if (ix >= 0 && iz >= 0 && ix < grid_nx_ && iz < grid_nz_) {
    const int step_x = d.x() > 0.0 ? 1 : -1;
    const int step_z = d.z() > 0.0 ? 1 : -1;
    double t_next_x = kInf, t_next_z = kInf, dt_x = kInf, dt_z = kInf;
    if (d.x() != 0.0) {
      const double boundary = grid_x0_cm_ + (ix + (d.x() > 0.0 ? 1 : 0)) * kGridCellCm;
      t_next_x = (boundary - o.x()) / d.x();
      dt_x = kGridCellCm / std::abs(d.x());
    }
    if (d.z() != 0.0) {
      const double boundary = grid_z0_cm_ + (iz + (d.z() > 0.0 ? 1 : 0)) * kGridCellCm;
      t_next_z = (boundary - o.z()) / d.z();
      dt_z = kGridCellCm / std::abs(d.z());
    }
    for (;;) {
      const std::size_t cell = static_cast<std::size_t>(iz) * grid_nx_ + ix;
      for (std::uint32_t k = cell_start_[cell]; k < cell_start_[cell + 1]; ++k) {
        const std::uint32_t item = cell_items_[k];
        if ((item & kBoxFlag) != 0) {
          const std::uint32_t b = item & ~kBoxFlag;
          const OrientedBox& box = boxes_[b];
          const Eigen::Vector3d lo = box_world_to_local_[b] * (o - box.centre_cm);
          const Eigen::Vector3d ld = box_world_to_local_[b] * d;
          double t_near = -kInf, t_far = kInf;
          bool miss = false;
          for (int a = 0; a < 3 && !miss; ++a) {
            double n = 0.0, f = 0.0;
            if (!slab(lo[a], ld[a], -box.half_extent_cm[a], box.half_extent_cm[a], n, f)) {
              miss = true;
              break;
            }
            t_near = std::max(t_near, n);
            t_far = std::min(t_far, f);
          }
          if (!miss && t_near <= t_far && t_near > kMinHitCm && t_near < best_t) {
            best_t = t_near;
            best_item = item;
          }
        } else {
          const RockPrism& p = prisms_[item];
          double xn = 0.0, xf = 0.0, zn = 0.0, zf = 0.0;
          if (!slab(o.x(), d.x(), p.x_min_cm, p.x_max_cm, xn, xf)) continue;
          if (!slab(o.z(), d.z(), p.z_min_cm, p.z_max_cm, zn, zf)) continue;
          const double t_near = std::max(xn, zn);
          const double t_far = std::min(xf, zf);
          if (t_near <= t_far && t_near > kMinHitCm && t_near < best_t) {
            best_t = t_near;
            best_item = item;
            best_axis = xn >= zn ? 0 : 2;
            best_sign = d[best_axis] > 0.0 ? -1.0 : 1.0;  // outward normal faces the ray
          }
        }
      }
      const double t_exit = std::min(t_next_x, t_next_z);
      if (best_t <= t_exit || t_exit >= t_limit) break;
      if (t_next_x < t_next_z) {
        ix += step_x;
        t_next_x += dt_x;
        if (ix < 0 || ix >= grid_nx_) break;
      } else {
        iz += step_z;
        t_next_z += dt_z;
        if (iz < 0 || iz >= grid_nz_) break;
      }
    }
  }

  if (best_t < kInf) {
    if ((best_item & kBoxFlag) != 0) {
      result = {best_t, SurfaceKind::kObject};
    } else {
      // Onto the rough rib: the rib surface is the face plane pushed out by the roughness field.
      const RockPrism& p = prisms_[best_item];
      const int a = best_axis;
      const double s = best_sign;
      const double face = a == 0 ? (s > 0.0 ? p.x_max_cm : p.x_min_cm) : (s > 0.0 ? p.z_max_cm : p.z_min_cm);
      const RoughnessField& field = a == 0 ? rib_x_rough_ : rib_z_rough_;
      const int u_axis = a == 0 ? 2 : 0;
      const auto eval = [&](double t, double* dg) {
        const Eigen::Vector3d q = o + t * d;
        const FieldSample h = field.sample(q[u_axis], q.y());
        *dg = s * d[a] - (h.d_du * d[u_axis] + h.d_dv * d.y());
        return s * (q[a] - face) - h.value;
      };
      const double lo = std::max(0.0, (face + s * rib_band_cm_ - o[a]) / d[a]);
      const double hi = (face - s * rib_band_cm_ - o[a]) / d[a];
      const std::optional<double> t = solve_crossing(eval, lo, hi, true, best_t);
      result = {t.value_or(best_t), SurfaceKind::kRib};
    }
  }

  // --- floor ---
  if (floor_lo < result.range_cm && floor_lo < max_range_cm) {
    double hi = std::min(floor_hi, max_range_cm);
    bool hi_below = floor_hi_below && hi == floor_hi;
    if (result.range_cm < hi) {
      hi = result.range_cm;
      hi_below = false;
    }
    const auto eval = [&](double t, double* dg) {
      const Eigen::Vector3d q = o + t * d;
      const FieldSample f = floor_height(q.x(), q.z());
      *dg = d.y() - (f.d_du * d.x() + f.d_dv * d.z());
      return q.y() - f.value;
    };
    if (const std::optional<double> t = solve_crossing(eval, floor_lo, hi, hi_below, floor_guess)) {
      if (*t < result.range_cm) result = {*t, SurfaceKind::kFloor};
    }
  }
  // --- roof ---
  if (roof_lo < result.range_cm && roof_lo < max_range_cm) {
    double hi = std::min(roof_hi, max_range_cm);
    bool hi_above = roof_hi_above && hi == roof_hi;
    if (result.range_cm < hi) {
      hi = result.range_cm;
      hi_above = false;
    }
    const auto eval = [&](double t, double* dg) {
      const Eigen::Vector3d q = o + t * d;
      const FieldSample c = roof_height(q.x(), q.z());
      *dg = (c.d_du * d.x() + c.d_dv * d.z()) - d.y();
      return c.value - q.y();
    };
    if (const std::optional<double> t = solve_crossing(eval, roof_lo, hi, hi_above, roof_guess)) {
      if (*t < result.range_cm) result = {*t, SurfaceKind::kRoof};
    }
  }

  if (result.range_cm > max_range_cm) return {};
  return result;
}

}  // namespace minemap::sim
