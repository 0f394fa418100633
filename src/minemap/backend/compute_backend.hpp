#pragma once
// The one seam between the algorithm and the hardware: a compute backend prepares clouds (kd-tree
// and device copies), pairs and sums for ICP, runs the slice filter and the voxel means, and places
// a metascan's scans. Everything else (Horn's method, the ICP schedule, the relaxation) runs on the
// host and calls a backend it is handed.
//
// Backends are values the caller owns, one file each:
//   CpuBackend     backend/cpu_backend.cpp: TBB over fixed blocks, deterministic
//   OpenClBackend  host/minemap/opencl/opencl_backend.cpp (target minemap::opencl, built where
//                  CMake finds OpenCL): one work-item per query; its runtime, programs and scratch
//                  buffers are its members
// The composition root (the CLI, tests, benchmarks) makes one, usually through make_backend
// (host/minemap/backend/make_backend.hpp), and passes it to map_survey or register_icp.
//
// Both backends compute the same float and double operations in the same order
// (minemap/shared/minemap_shared.h): on a device with double precision they return the same bits.
#include <Eigen/Core>
#include <cmath>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "minemap/filter/slice_filter.hpp"
#include "minemap/filter/voxel_filter.hpp"
#include "minemap/search/pair_sums.hpp"
#include "minemap/search/pairing.hpp"
#include "minemap/search/plane_sums.hpp"

namespace minemap {

/// A backend failed while running (an OpenCL device ran out of resources or was lost), or could
/// not be set up. map_survey catches it and matches the survey again on a CPU backend.
class BackendError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// One cloud of a union of clouds (a metascan, slam/local_map.cpp): its points and the rigid
/// transform T_frame_cloud that places them in the union's frame.
struct UnionPart {
  std::span<const Eigen::Vector3f> points_cm;
  /// The same points as this backend prepared them (a device copy), or null (read back from a spill).
  const PreparedCloud* cloud = nullptr;
  Pose frame_from_cloud = Pose::Identity();
};

/// The host's placed_within (ComputeBackend): each part's points in parallel tasks (TBB).
std::vector<std::vector<Eigen::Vector3f>> placed_within_on_host(std::span<const UnionPart> parts,
                                                                const Eigen::Vector3d& min_cm,
                                                                const Eigen::Vector3d& max_cm);

/// Thread-safety: a backend is used from one thread at a time (it parallelises internally, and owns
/// scratch state); the clouds it prepares are immutable and may be read from any thread, as long as
/// the backend lives.
class ComputeBackend {
 public:
  virtual ~ComputeBackend() = default;
  /// "cpu" or "opencl".
  virtual std::string name() const = 0;
  /// The device, for reports: "CPU (TBB bucket kd-tree)", "Portable Computing Language / cpu-... (driver ...)".
  virtual std::string device_description() const = 0;

  /// Builds the kd-tree (and device copies) of a cloud used as data and/or model: now, or where
  /// the backend allows it, when first searched (TreeBuild; the OpenCL backend uploads at once).
  virtual std::shared_ptr<const PreparedCloud> prepare(std::vector<Eigen::Vector3f> points_cm,
                                                       const KdTreeSettings& tree_settings,
                                                       TreeBuild when = TreeBuild::kNow) = 0;

  /// prepare() for each cloud, in order: one tree per cloud, the same trees as one call each. The
  /// CPU backend builds them in parallel (a survey's scans: each tree alone is too small to split
  /// well); this default builds them in turn.
  virtual std::vector<std::shared_ptr<const PreparedCloud>> prepare_many(
      std::vector<std::vector<Eigen::Vector3f>> clouds_cm, const KdTreeSettings& tree_settings,
      TreeBuild when = TreeBuild::kNow) {
    std::vector<std::shared_ptr<const PreparedCloud>> prepared;
    prepared.reserve(clouds_cm.size());
    for (auto& cloud : clouds_cm) prepared.push_back(prepare(std::move(cloud), tree_settings, when));
    return prepared;
  }

  /// Pairs every data point with its closest point over all `models` within the pair bound and
  /// returns the point-to-point sums, centred on the data cloud's centroid. Clouds must come from
  /// this backend's prepare().
  virtual PairSums pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                SearchMethod method, const PairingSettings& settings) = 0;

  /// Pairs as pair_and_sum does and returns the point-to-plane sums (search/plane_sums.hpp) of the
  /// data's planes, `data_normals` one per data point (zero: no plane), centred on the data
  /// cloud's centroid. This default pairs with nearest() and sums on the host; a backend that sums
  /// while it searches must give the same bits (the same blocks, in the same order).
  virtual PlaneSums pair_and_plane_sum(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                       SearchMethod method, const PairingSettings& settings,
                                       std::span<const Eigen::Vector3f> data_normals) {
    return plane_sums(nearest(data, models, method, settings), data.points(), data_normals, data.centroid_cm());
  }

  /// The closest pair of every data point (tests, diagnostics, and the default point-to-plane sums).
  virtual std::vector<NearestPair> nearest(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                           SearchMethod method, const PairingSettings& settings) = 0;

  /// The paper's slice filter (filter/slice_filter.hpp). Throws std::invalid_argument for invalid
  /// settings; a scan without slices comes back unchanged, as one output slice (unfiltered_result).
  SliceFilterResult filter_slices(const Scan& scan, const SliceFilterSettings& settings) {
    settings.validate();
    return scan.has_slices() ? filter_slices_checked(scan, settings) : unfiltered_result(scan, name());
  }

  /// The voxel means of a cloud (filter/voxel_filter.hpp), and of `values` (one per point) into
  /// `value_means` when that is given: voxel_mean_filter's result bit for bit on every backend.
  /// Throws std::invalid_argument where voxel_mean_filter does.
  std::vector<Eigen::Vector3f> voxel_means(std::span<const Eigen::Vector3f> points_cm, float voxel_cm,
                                           std::span<const float> values = {},
                                           std::vector<float>* value_means = nullptr) {
    if (!(voxel_cm > 0.0f) || !std::isfinite(voxel_cm)) throw std::invalid_argument("voxel size must be a finite length > 0 cm");
    if (value_means != nullptr && values.size() != points_cm.size()) {
      throw std::invalid_argument("voxel means: one value per point expected");
    }
    return voxel_means_checked(points_cm, voxel_cm, value_means ? values : std::span<const float>{}, value_means);
  }

  /// Each part's points moved into the union's frame (in double, each row's terms added in
  /// shared::mm_place_point's order, then cast to float), those outside the box [min_cm, max_cm]
  /// left out, in point order: one list per part, the same bits on every backend. Parts with a
  /// cloud of this backend's may be placed on its device.
  virtual std::vector<std::vector<Eigen::Vector3f>> placed_within(std::span<const UnionPart> parts,
                                                                  const Eigen::Vector3d& min_cm,
                                                                  const Eigen::Vector3d& max_cm) {
    return placed_within_on_host(parts, min_cm, max_cm);
  }

  /// Whether voxel_means may be called from several threads at once (the host's code is a pure
  /// function): a survey's scans are then reduced in parallel tasks, otherwise one after another.
  virtual bool concurrent_voxel_means() const { return false; }

 protected:
  /// voxel_means for valid arguments (`value_means` null: no values). This default is the host's.
  virtual std::vector<Eigen::Vector3f> voxel_means_checked(std::span<const Eigen::Vector3f> points_cm, float voxel_cm,
                                                           std::span<const float> values,
                                                           std::vector<float>* value_means) {
    return value_means ? voxel_mean_filter(points_cm, voxel_cm, values, *value_means)
                       : voxel_mean_filter(points_cm, voxel_cm);
  }

  /// filter_slices for a scan with slices and validated settings.
  virtual SliceFilterResult filter_slices_checked(const Scan& scan, const SliceFilterSettings& settings) = 0;
};

/// The TBB backend (backend/cpu_backend.cpp). Always available.
std::unique_ptr<ComputeBackend> make_cpu_backend();

}  // namespace minemap
