#pragma once
// The simulated mine as geometry: rough floor and roof height fields, rock prisms (pillars and the
// solid rock around the workings) with rough ribs, and smooth oriented boxes (timber sets, rails,
// rubble, a broken roof bar). Ray casting is analytic: slab tests against the boxes through a 2D
// grid over x-z (so only primitives along the ray are touched), then safeguarded Newton steps onto
// the rough surfaces, whose bumps are functions of WORLD position.
//
// Frame: 3DTK's (left-handed, cm): x across the drive, y up, z along the drive. The drive's centre
// line is x = 0; scan 0 stands near z = 0 with the floor near y = 0.
//
// Thread-safety: a MineWorld is immutable after construction; every const member (ray casting
// included) is safe to call from any number of threads at once.
#include <Eigen/Core>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "minemap/sim/gradient_noise.hpp"
#include "minemap/sim/mine_simulator.hpp"

namespace minemap::sim {

/// What a beam hit.
enum class SurfaceKind : std::uint8_t { kNone, kFloor, kRoof, kRib, kObject };

struct RayHit {
  double range_cm = std::numeric_limits<double>::infinity();
  SurfaceKind kind = SurfaceKind::kNone;
  bool hit() const { return kind != SurfaceKind::kNone; }
};

/// Solid rock from far below the floor to far above the roof: a pillar or the rock around the
/// workings. Axis-aligned in x-z; its four ribs are rough.
struct RockPrism {
  double x_min_cm = 0.0;
  double x_max_cm = 0.0;
  double z_min_cm = 0.0;
  double z_max_cm = 0.0;
};

/// What a smooth box stands for (for drawing and statistics).
enum class ObjectKind : std::uint8_t { kRoofBar, kPost, kRail, kRubble, kBrokenBar };

/// A smooth solid: a box with arbitrary orientation.
struct OrientedBox {
  Eigen::Vector3d centre_cm = Eigen::Vector3d::Zero();
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();  ///< columns: the box axes in the world
  Eigen::Vector3d half_extent_cm = Eigen::Vector3d::Zero();
  ObjectKind kind = ObjectKind::kRubble;
};

/// Where the entries run: x spans of the drive (index 0) and the parallel entries.
struct EntrySpan {
  double x_min_cm = 0.0;
  double x_max_cm = 0.0;
};

/// Precomputed per viewpoint (a scan pose): values every ray from it needs.
struct ViewPoint {
  Eigen::Vector3d origin_cm = Eigen::Vector3d::Zero();
  double floor_offset_cm = 0.0;  ///< smooth floor above the mine's reference plane, here
  double roof_offset_cm = 0.0;   ///< smooth roof above the reference plane plus the seam height
};

class MineWorld {
 public:
  /// Builds the mine for `settings`. `drive_end_z_cm` is where the last scan pose stands: the mine
  /// reaches past max(drive end, settings.drive_length_cm), with the broken roof bar just beyond it.
  MineWorld(const MineSettings& settings, double drive_end_z_cm);

  /// First surface along the ray within (0, max_range_cm]; `direction` must be a unit vector.
  RayHit cast_ray(const ViewPoint& view, const Eigen::Vector3d& direction, double max_range_cm) const;
  RayHit cast_ray(const Eigen::Vector3d& origin_cm, const Eigen::Vector3d& direction, double max_range_cm) const {
    return cast_ray(view_point(origin_cm), direction, max_range_cm);
  }
  ViewPoint view_point(const Eigen::Vector3d& origin_cm) const;

  /// Floor height y(x, z) with its gradient (d_du = dy/dx, d_dv = dy/dz), roughness included.
  FieldSample floor_height(double x_cm, double z_cm) const;
  /// Roof height y(x, z) with its gradient, roughness included.
  FieldSample roof_height(double x_cm, double z_cm) const;
  /// Floor without the small-scale roughness (where rails and rubble are laid).
  double smooth_floor_cm(double x_cm, double z_cm) const;

  /// Whether `p` lies in open space (above the floor, under the roof, outside every solid).
  bool in_open_space(const Eigen::Vector3d& p_cm) const;

  std::span<const RockPrism> prisms() const { return prisms_; }
  std::span<const OrientedBox> boxes() const { return boxes_; }
  std::span<const EntrySpan> entries() const { return entries_; }
  /// z of the cross-cuts through the pillar row next to the drive on `side` (+1 right, -1 left):
  /// the middles of the gaps between its pillars, ascending.
  std::vector<double> drive_crosscuts_z(int side) const;
  double z_start_cm() const { return z_start_cm_; }
  double z_end_cm() const { return z_end_cm_; }
  /// z of the broken roof bar (NaN when there is none).
  double broken_bar_z_cm() const { return broken_bar_z_cm_; }

 private:
  double undulation(double z_cm, double* d_dz) const;
  double floor_plane(double x_cm, double z_cm) const { return slope_ * z_cm + cross_slope_ * x_cm; }
  double smooth_roof_cm(double x_cm, double z_cm) const;

  void build_layout(const MineSettings& settings, double drive_end_z_cm);
  void build_grid();
  /// x of the drive's rib on `side` (+1 right, -1 left) at z, or NaN where a cross-cut opens.
  double drive_rib_x(int side, double z_cm, double clearance_cm) const;

  // --- surfaces ---
  double slope_ = 0.0;        ///< dy/dz of the reference plane (elevation gain over the drive)
  double cross_slope_ = 0.0;  ///< dy/dx of the reference plane
  double undulation_amp_cm_[2] = {0.0, 0.0};
  double undulation_wavenumber_[2] = {0.0, 0.0};  ///< rad per cm
  double undulation_bound_cm_ = 0.0;
  double seam_height_cm_ = 0.0;
  RoughnessField seam_roll_;     ///< long waves both floor and roof follow (the seam rolls)
  RoughnessField seam_height_;   ///< roof-only variation of the seam thickness
  RoughnessField floor_rough_;   ///< (u, v) = (x, z)
  RoughnessField roof_rough_;    ///< (u, v) = (x, z)
  RoughnessField rib_x_rough_;   ///< ribs facing +-x: (u, v) = (z, y)
  RoughnessField rib_z_rough_;   ///< ribs facing +-z: (u, v) = (x, y)
  double floor_band_cm_ = 0.0;   ///< |floor - plane| bound
  double roof_band_cm_ = 0.0;    ///< |roof - plane - seam height| bound
  double rib_band_cm_ = 0.0;     ///< rib roughness bound
  double floor_smooth_slope_ = 0.0;  ///< |gradient| bound of the smooth floor minus the plane
  double roof_smooth_slope_ = 0.0;   ///< same for the smooth roof

  // --- solids ---
  std::vector<RockPrism> prisms_;
  std::vector<OrientedBox> boxes_;
  std::vector<Eigen::Matrix3d> box_world_to_local_;  ///< axes transposed, per box
  std::vector<EntrySpan> entries_;
  struct PillarRow {
    int side = 0;                ///< +1 right of the drive, -1 left
    std::vector<int> pillars;    ///< indices into prisms_, sorted by z
  };
  std::vector<PillarRow> rows_;
  int drive_row_[2] = {-1, -1};  ///< rows_ index bordering the drive on the left [0] / right [1]
  double rock_x_cm_[2] = {0.0, 0.0};  ///< inner face of the surrounding rock, left / right
  double z_start_cm_ = 0.0;
  double z_end_cm_ = 0.0;
  double broken_bar_z_cm_ = std::numeric_limits<double>::quiet_NaN();

  // --- 2D grid over x-z: per cell, the solids whose footprint touches it (CSR layout) ---
  double grid_x0_cm_ = 0.0;
  double grid_z0_cm_ = 0.0;
  int grid_nx_ = 0;
  int grid_nz_ = 0;
  std::vector<std::uint32_t> cell_start_;
  std::vector<std::uint32_t> cell_items_;  ///< prism index, or box index | kBoxFlag
};

}  // namespace minemap::sim
