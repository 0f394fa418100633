#pragma once
// Internal (not installed). Paper, section IV.C, and the voxel means: one scan in, a prepared scan
// out. A scan is reduced as MappingSettings say (voxel means, or the paper's slice filter, or every
// n-th point of a scan without slices), with a denser model cloud where the settings ask for one
// and the health check's probe; then each cloud gets its kd-tree on the backend, and the model its
// planes. map_survey prepares the scans a chunk at a time (prepare_all: the voxel means in parallel,
// the chunk's trees in one prepare_many call); `minemap watch` one at a time (prepare): both reduce
// each scan with the same function and build the same trees.
//
// Thread-safety: uses the backend, one thread at a time.
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/core/scan.hpp"
#include "minemap/filter/deskew.hpp"
#include "minemap/registration/match_information.hpp"
#include "minemap/slam/mapping_settings.hpp"
#include "minemap/slam/run_control.hpp"

namespace minemap::detail {

/// A scan's clouds as the matcher uses them. Immutable once made.
struct PreparedScan {
  std::shared_ptr<const PreparedCloud> cloud;        ///< data: matched against others
  std::shared_ptr<const PreparedCloud> model_cloud;  ///< model: others are matched against it (may be `cloud`)
  std::shared_ptr<const PreparedCloud> probe;        ///< every health.probe_stride-th data point: what judging searches
  std::optional<SurfaceNormals> planes;              ///< its model's planes, own frame (health, loop edges)
  std::shared_ptr<const std::vector<Eigen::Vector3f>> used_points_cm;  ///< the data points, for the map
  /// Their intensities (kVoxel: each voxel's mean), for the map's colours; null where the scan has none.
  std::shared_ptr<const std::vector<float>> used_intensity;
  std::size_t points_in = 0;
  std::size_t outliers_replaced = 0;
  /// A moving sensor's sweep (filter/deskew.hpp): its middle on the file's clock (NaN: no times)...
  double stamp_s = std::numeric_limits<double>::quiet_NaN();
  double sweep_s = 0.0;  ///< ...and its duration (0: not one sweep, never deskewed)
  std::optional<Pose> sweep_motion;  ///< the motion over the sweep its clouds were deskewed by
  const SurfaceNormals* planes_or_null() const { return planes ? &*planes : nullptr; }
};

/// Sets used_points_cm to the data cloud's own points (prepared.cloud must be set): an aliasing
/// pointer, so the map's points keep the cloud alive and are its points, not a copy of them.
void share_with_the_map(PreparedScan& prepared);

class ScanPreparation {
 public:
  ScanPreparation(const MappingSettings& settings, ComputeBackend& backend) : settings_(settings), backend_(backend) {}

  /// One scan, alone (its trees by prepare); deskewed by `sweep_motion` (the sensor's motion over
  /// the sweep, its own frame, cm) when `timing` holds the points' times.
  PreparedScan prepare(const Scan& scan, RunControl& control, const SweepTiming& timing = {},
                       const std::optional<Pose>& sweep_motion = std::nullopt);
  /// The timing of a scan as MotionSettings::deskew asks (empty: not deskewed).
  SweepTiming timing_of(const Scan& scan) const;
  /// When the scans' model trees are built (a data or probe tree: on first use, always).
  TreeBuild model_trees_when() const;
  /// Every scan of `scans` (a part of a survey), in order (the voxel means in parallel, the trees in
  /// one prepare_many call each for data, models and probes). Its progress is the matching's.
  std::vector<PreparedScan> prepare_all(std::span<const Scan> scans, RunControl& control);
  /// True once a scan without slices skipped the slice filter it was asked for (a note).
  bool skipped_slice_filter() const { return skipped_slice_filter_; }

 private:
  /// A scan's clouds before their trees: data, the denser model (if any), the health probe (if any).
  struct Reduced {
    std::vector<Eigen::Vector3f> data, model, probe;
    std::vector<float> intensity;  ///< of `data`, where the scan has intensities
    bool has_model = false, has_probe = false;
    std::size_t outliers_replaced = 0;
  };
  struct VoxelMeans {
    std::vector<Eigen::Vector3f> data, model;
    std::vector<float> intensity;  ///< each data voxel's mean intensity (scans that carry one)
  };
  /// The prepared scan's points, intensities and counts, before its trees.
  void keep_for_the_map(PreparedScan& prepared, const Scan& scan, Reduced& reduced) const;
  VoxelMeans voxel_means(const Scan& scan) const;
  /// `scan` reduced as the settings say (voxel: its voxel means, computed before).
  Reduced reduce(const Scan& scan, VoxelMeans voxel, RunControl& control);
  std::vector<Eigen::Vector3f> filtered_model(const Scan& scan, bool& dense) const;

  const MappingSettings& settings_;
  ComputeBackend& backend_;
  bool skipped_slice_filter_ = false;
};

}  // namespace minemap::detail
