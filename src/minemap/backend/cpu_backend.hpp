#pragma once
// The CPU compute backend: TBB over fixed blocks of queries (pairing) and over slices (the slice
// filter). Each block of kPairSumBlock queries sums its pairs in double; blocks are added in
// index order, so every thread count gives the same bits, and so does the OpenCL backend on a
// device with double precision.
#include "minemap/backend/compute_backend.hpp"

namespace minemap {

/// Thread-safety: as ComputeBackend; it holds no state, so one instance may be shared anyway.
/// Threads: those of the calling TBB arena (tbb::task_arena limits them).
class CpuBackend final : public ComputeBackend {
 public:
  std::string name() const override { return "cpu"; }
  std::string device_description() const override { return "CPU (TBB bucket kd-tree)"; }
  std::shared_ptr<const PreparedCloud> prepare(std::vector<Eigen::Vector3f> points_cm,
                                               const KdTreeSettings& tree_settings,
                                               TreeBuild when = TreeBuild::kNow) override;
  std::vector<std::shared_ptr<const PreparedCloud>> prepare_many(std::vector<std::vector<Eigen::Vector3f>> clouds_cm,
                                                                 const KdTreeSettings& tree_settings,
                                                                 TreeBuild when = TreeBuild::kNow) override;
  PairSums pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                        const PairingSettings& settings) override;
  /// Sums each block's pairs as it finds them (the default's bits: plane_sums' blocks).
  PlaneSums pair_and_plane_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                               const PairingSettings& settings, std::span<const Eigen::Vector3f> data_normals) override;
  std::vector<NearestPair> nearest(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                   SearchMethod method, const PairingSettings& settings) override;
  /// The voxel means are the host's voxel_mean_filter (the base class's), a pure function.
  bool concurrent_voxel_means() const override { return true; }

 protected:
  SliceFilterResult filter_slices_checked(const Scan& scan, const SliceFilterSettings& settings) override;
};

}  // namespace minemap
