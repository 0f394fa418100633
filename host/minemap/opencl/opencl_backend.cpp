// The OpenCL compute backend (opencl_backend.hpp). Trees and clouds are uploaded once when
// prepared; each ICP iteration launches one search kernel per model (the union of neighbours keeps
// the closest pair across launches) and one reduction kernel. With double precision on the device,
// pair_sums_blocks makes the CPU backend's per-block sums bit for bit and the host adds them in
// block order (same poses as the CPU); without it, pair_sums reduces in float to 64 x 17 partial
// sums, added by the host in double in group order. Deterministic either way, no atomics.
// The slice filter: one launch filters all kept slices of a scan, one work-item per slice; each
// slice writes into its own input range (output never exceeds input). The voxel means: five
// launches per cloud (kernels/voxel_means.cl), integer atomics only, the host's bits. A metascan's
// union: one launch per scan placing its device copy (kernels/union.cl), read back once.
#include "minemap/opencl/opencl_backend.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <vector>

#include "minemap/opencl/runtime.hpp"

namespace minemap::opencl {
namespace {

constexpr std::size_t kSumTerms = MM_SUM_TERMS;
constexpr std::size_t kReductionGroups = 64;
constexpr std::size_t kReductionGroupSize = 128;
constexpr std::size_t kSearchGroupSize = 64;
constexpr std::size_t kBruteTile = MM_BRUTE_TILE;

cl_float4 to_float4(float x, float y, float z, float w) { return cl_float4{{x, y, z, w}}; }

/// Rows of a rigid transform (rotation row in xyz, translation in w), cast to float as the CPU does.
std::array<cl_float4, 3> rows_of(const Pose& pose) {
  std::array<cl_float4, 3> rows{};
  for (int r = 0; r < 3; ++r) {
    rows[r] = to_float4(static_cast<float>(pose(r, 0)), static_cast<float>(pose(r, 1)), static_cast<float>(pose(r, 2)),
                        static_cast<float>(pose(r, 3)));
  }
  return rows;
}

template <typename T>
cl::Buffer upload(Runtime& runtime, const std::vector<T>& host) {
  // Zero-sized buffers are invalid in OpenCL: keep one dummy element for empty clouds.
  const std::size_t bytes = std::max<std::size_t>(1, host.size()) * sizeof(T);
  if (host.empty()) {
    std::vector<T> dummy(1);
    return runtime.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, bytes, dummy.data());
  }
  return runtime.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, bytes, const_cast<T*>(host.data()));
}

/// A cloud on the device: its points and its tree, uploaded once. Immutable after construction.
class OpenClPreparedCloud final : public PreparedCloud {
 public:
  OpenClPreparedCloud(Runtime& runtime, std::vector<Eigen::Vector3f> points, const KdTreeSettings& settings)
      : PreparedCloud(std::move(points), settings) {
    std::vector<cl_float4> data;
    data.reserve(this->points().size());
    for (const auto& p : this->points()) data.push_back(to_float4(p.x(), p.y(), p.z(), 0.0f));
    const std::size_t bytes_needed = data.size() * (sizeof(cl_float4) * 3 + sizeof(cl_int2));
    if (bytes_needed > runtime.max_alloc_bytes()) {
      throw DeviceError("cloud of " + std::to_string(data.size()) + " points exceeds the device's allocation limit");
    }
    data_ = upload(runtime, data);
    const auto& t = tree();
    nodes_ = upload(runtime, std::vector<KdNode>(t.nodes().begin(), t.nodes().end()));
    tree_points_ = upload(runtime, std::vector<KdPoint>(t.points().begin(), t.points().end()));
    leaf_means_ = upload(runtime, std::vector<std::array<float, 4>>(t.leaf_means().begin(), t.leaf_means().end()));
  }

  cl::Buffer data_, nodes_, tree_points_, leaf_means_;
};

class OpenClBackend final : public ComputeBackend {
 public:
  explicit OpenClBackend(std::shared_ptr<Runtime> runtime) : runtime_(std::move(runtime)) {
    try {
      nearest_in_tree_ = cl::Kernel(runtime_->program(), "nearest_in_tree");
      nearest_brute_force_ = cl::Kernel(runtime_->program(), "nearest_brute_force");
      pair_sums_ = cl::Kernel(runtime_->program(), "pair_sums");
      if (runtime_->has_fp64()) pair_sums_blocks_ = cl::Kernel(runtime_->program(), "pair_sums_blocks");
      if (runtime_->has_fp64()) place_within_ = cl::Kernel(runtime_->program(), "place_within");
      filter_slices_ = cl::Kernel(runtime_->program(), "filter_slices");
      if (runtime_->has_voxel_means()) {
        voxel_insert_ = cl::Kernel(runtime_->program(), "voxel_insert");
        voxel_scan_ = cl::Kernel(runtime_->program(), "voxel_scan");
        voxel_cells_ = cl::Kernel(runtime_->program(), "voxel_cells");
        voxel_members_ = cl::Kernel(runtime_->program(), "voxel_members");
        voxel_sum_ = cl::Kernel(runtime_->program(), "voxel_sum");
      }
      reduction_group_size_ = runtime_->work_group_size(pair_sums_, kReductionGroupSize);
      if (runtime_->work_group_size(nearest_brute_force_, kBruteTile) < kBruteTile) {
        throw DeviceError("device work-group limit is below the brute-force tile of " + std::to_string(kBruteTile));
      }
      partials_ = runtime_->buffer(CL_MEM_WRITE_ONLY, kReductionGroups * kSumTerms * sizeof(float));
    } catch (const DeviceError&) {
      throw;
    } catch (...) {
      rethrow_as_device_error("creating the OpenCL kernels");
    }
  }

  std::string name() const override { return "opencl"; }
  std::string device_description() const override { return runtime_->description(); }

  /// Always builds the tree at once: the device copies are made here (`when` is a CPU saving).
  std::shared_ptr<const PreparedCloud> prepare(std::vector<Eigen::Vector3f> points_cm,
                                               const KdTreeSettings& tree_settings,
                                               TreeBuild /*when*/ = TreeBuild::kNow) override {
    try {
      return std::make_shared<OpenClPreparedCloud>(*runtime_, std::move(points_cm), tree_settings);
    } catch (const DeviceError&) {
      throw;
    } catch (...) {
      rethrow_as_device_error("uploading a cloud to the OpenCL device");
    }
  }

  PairSums pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                        const PairingSettings& settings) override {
    PairSums total;
    total.reference_cm = data.centroid_cm();
    const auto& cloud = as_device(data);
    const auto n = static_cast<cl_int>(data.points().size());
    try {
      if (n == 0 || !search(cloud, n, models, method, settings)) return total;
      // Only the per-group (or per-block) partial sums cross the bus.
      const float scale_squared = settings.robust_scale_cm * settings.robust_scale_cm;
      if (runtime_->has_fp64()) return sums_by_block(cloud, n, data.centroid_cm(), scale_squared);
      // The centroid is float-representable (PreparedCloud rounds it), so the device subtracts
      // exactly the reference the host adds back in t = (c_m + r) - R (c_p + r).
      const Eigen::Vector3f r = data.centroid_cm().cast<float>();
      const cl_float4 reference = to_float4(r.x(), r.y(), r.z(), 0.0f);
      int arg = 0;
      pair_sums_.setArg(arg++, cloud.data_);
      pair_sums_.setArg(arg++, best_pair_);
      pair_sums_.setArg(arg++, n);
      pair_sums_.setArg(arg++, reference);
      pair_sums_.setArg(arg++, scale_squared);
      pair_sums_.setArg(arg++, partials_);
      pair_sums_.setArg(arg++, cl::Local(kSumTerms * reduction_group_size_ * sizeof(float)));
      runtime_->launch(pair_sums_, kReductionGroups * reduction_group_size_, reduction_group_size_);
      std::array<float, kReductionGroups * kSumTerms> partial{};
      runtime_->queue().enqueueReadBuffer(partials_, CL_TRUE, 0, sizeof(partial), partial.data());
      for (std::size_t g = 0; g < kReductionGroups; ++g) {
        total += PairSums::from_terms(partial.data() + g * kSumTerms, total.reference_cm);
      }
    } catch (const DeviceError&) {
      throw;
    } catch (...) {
      rethrow_as_device_error("OpenCL pairing");
    }
    return total;
  }

  /// The sums as the CPU makes them (kernel pair_sums_blocks): bit-identical to the CPU backend.
  /// Reads back kSumTerms doubles per block of kPairSumBlock data points (about 2 % of the pairs' bytes).
  PairSums sums_by_block(const OpenClPreparedCloud& cloud, cl_int n, const Eigen::Vector3d& reference,
                         float scale_squared) {
    const std::size_t blocks = (static_cast<std::size_t>(n) + kPairSumBlock - 1) / kPairSumBlock;
    if (block_partials_count_ < blocks) {
      block_partials_ = runtime_->buffer(CL_MEM_WRITE_ONLY, blocks * kSumTerms * sizeof(double));
      block_partials_count_ = blocks;
    }
    int arg = 0;
    pair_sums_blocks_.setArg(arg++, cloud.data_);
    pair_sums_blocks_.setArg(arg++, best_pair_);
    pair_sums_blocks_.setArg(arg++, n);
    pair_sums_blocks_.setArg(arg++, reference.x());
    pair_sums_blocks_.setArg(arg++, reference.y());
    pair_sums_blocks_.setArg(arg++, reference.z());
    pair_sums_blocks_.setArg(arg++, scale_squared);
    pair_sums_blocks_.setArg(arg++, block_partials_);
    const std::size_t group = std::min<std::size_t>(64, runtime_->work_group_size(pair_sums_blocks_, 64));
    runtime_->launch(pair_sums_blocks_, (blocks + group - 1) / group * group, group);
    std::vector<double> partial(blocks * kSumTerms);
    runtime_->queue().enqueueReadBuffer(block_partials_, CL_TRUE, 0, partial.size() * sizeof(double), partial.data());
    PairSums total;
    total.reference_cm = reference;
    for (std::size_t b = 0; b < blocks; ++b) total += PairSums::from_terms(partial.data() + b * kSumTerms, reference);
    return total;
  }

  std::vector<NearestPair> nearest(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                                   const PairingSettings& settings) override {
    const auto& cloud = as_device(data);
    const auto n = static_cast<cl_int>(data.points().size());
    std::vector<NearestPair> result(static_cast<std::size_t>(n));
    try {
      if (n == 0 || !search(cloud, n, models, method, settings)) return result;
      std::vector<cl_float4> pairs(static_cast<std::size_t>(n));
      std::vector<cl_int2> refs(static_cast<std::size_t>(n));
      runtime_->queue().enqueueReadBuffer(best_pair_, CL_TRUE, 0, pairs.size() * sizeof(cl_float4), pairs.data());
      runtime_->queue().enqueueReadBuffer(best_ref_, CL_TRUE, 0, refs.size() * sizeof(cl_int2), refs.data());
      for (std::size_t i = 0; i < result.size(); ++i) {
        if (pairs[i].s[3] < 0.0f) continue;
        result[i] = {pairs[i].s[3], refs[i].s[0], refs[i].s[1], Eigen::Vector3f(pairs[i].s[0], pairs[i].s[1], pairs[i].s[2])};
      }
    } catch (const DeviceError&) {
      throw;
    } catch (...) {
      rethrow_as_device_error("OpenCL nearest-neighbour search");
    }
    return result;
  }

 protected:
  SliceFilterResult filter_slices_checked(const Scan& scan, const SliceFilterSettings& settings) override {
    SliceFilterResult result;
    result.backend = "opencl";
    result.points_in = scan.size();
    const std::vector<std::size_t> kept_indices = kept_slice_indices(scan, settings);
    if (scan.empty()) {
      // Slices without points (no returns): one empty output slice per kept slice, as on the CPU;
      // nothing to launch (OpenCL rejects zero-size buffers).
      result.slice_offsets.assign(kept_indices.size() + 1, 0);
      return result;
    }
    try {
      cl::Kernel& kernel = filter_slices_;
      Runtime* runtime = runtime_.get();
      std::vector<cl_float4> points(scan.size());
      for (std::size_t i = 0; i < scan.size(); ++i) {
        points[i] = cl_float4{{scan.points_cm[i].x(), scan.points_cm[i].y(), scan.points_cm[i].z(), 0.0f}};
      }
      std::vector<cl_int> offsets(scan.slice_offsets.begin(), scan.slice_offsets.end());
      const std::vector<cl_int> kept(kept_indices.begin(), kept_indices.end());
      const std::size_t point_bytes = points.size() * sizeof(cl_float4);
      cl::Buffer in = runtime->buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, point_bytes, points.data());
      cl::Buffer slice_offsets =
          runtime->buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, offsets.size() * sizeof(cl_int), offsets.data());
      cl::Buffer kept_slices = runtime->buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, kept.size() * sizeof(cl_int),
                                               const_cast<cl_int*>(kept.data()));
      cl::Buffer out = runtime->buffer(CL_MEM_WRITE_ONLY, point_bytes);
      cl::Buffer counts = runtime->buffer(CL_MEM_WRITE_ONLY, kept.size() * sizeof(cl_int));
      cl::Buffer replaced = runtime->buffer(CL_MEM_WRITE_ONLY, kept.size() * sizeof(cl_int));
      int arg = 0;
      kernel.setArg(arg++, in);
      kernel.setArg(arg++, slice_offsets);
      kernel.setArg(arg++, kept_slices);
      kernel.setArg(arg++, static_cast<cl_int>(kept.size()));
      kernel.setArg(arg++, static_cast<cl_int>(settings.median_window / 2));
      kernel.setArg(arg++, settings.outlier_threshold_cm);
      kernel.setArg(arg++, settings.min_point_spacing_cm);
      kernel.setArg(arg++, static_cast<cl_int>(settings.median_enabled ? 1 : 0));
      kernel.setArg(arg++, static_cast<cl_int>(settings.reduction_enabled ? 1 : 0));
      kernel.setArg(arg++, out);
      kernel.setArg(arg++, counts);
      kernel.setArg(arg++, replaced);
      const std::size_t group = runtime->work_group_size(kernel, 64);
      auto& queue = runtime->queue();
      runtime->launch(kernel, round_up(kept.size(), group), group);
      std::vector<cl_float4> filtered(points.size());
      std::vector<cl_int> out_counts(kept.size()), out_replaced(kept.size());
      // Blocking reads: each returns its own status (a failed non-blocking one might go unnoticed).
      queue.enqueueReadBuffer(out, CL_TRUE, 0, point_bytes, filtered.data());
      queue.enqueueReadBuffer(counts, CL_TRUE, 0, out_counts.size() * sizeof(cl_int), out_counts.data());
      queue.enqueueReadBuffer(replaced, CL_TRUE, 0, out_replaced.size() * sizeof(cl_int), out_replaced.data());
      result.slice_offsets.push_back(0);
      for (std::size_t k = 0; k < kept.size(); ++k) {
        const auto begin = static_cast<std::size_t>(offsets[static_cast<std::size_t>(kept[k])]);
        result.points_in_kept_slices += static_cast<std::size_t>(offsets[static_cast<std::size_t>(kept[k]) + 1]) - begin;
        result.outliers_replaced += static_cast<std::size_t>(out_replaced[k]);
        for (int i = 0; i < out_counts[k]; ++i) {
          const cl_float4& p = filtered[begin + static_cast<std::size_t>(i)];
          result.points_cm.emplace_back(p.s[0], p.s[1], p.s[2]);
        }
        result.slice_offsets.push_back(static_cast<std::uint32_t>(result.points_cm.size()));
      }
      return result;
    } catch (...) {
      rethrow_as_device_error("OpenCL slice filter");
    }
  }

  std::vector<std::vector<Eigen::Vector3f>> placed_within(std::span<const UnionPart> parts, const Eigen::Vector3d& min_cm,
                                                          const Eigen::Vector3d& max_cm) override {
    // On the device the parts it holds (all of them while mapping: nothing is let go of on a
    // device); the rest, and every part on a device without double precision, on the host.
    std::vector<const OpenClPreparedCloud*> on_device(parts.size(), nullptr);
    std::vector<std::size_t> offsets(parts.size(), 0), on_host;
    std::size_t total = 0;
    for (std::size_t k = 0; k < parts.size(); ++k) {
      const auto* cloud = runtime_->has_fp64() ? dynamic_cast<const OpenClPreparedCloud*>(parts[k].cloud) : nullptr;
      if (cloud != nullptr && !parts[k].points_cm.empty() && cloud->points().data() == parts[k].points_cm.data() &&
          cloud->points().size() == parts[k].points_cm.size()) {
        on_device[k] = cloud;
        offsets[k] = total;
        total += parts[k].points_cm.size();
      } else {
        on_host.push_back(k);
      }
    }
    std::vector<std::vector<Eigen::Vector3f>> placed(parts.size());
    if (total > 0) {
      try {
        if (total > union_capacity_) {
          union_capacity_ = std::max(total, 2 * union_capacity_);
          union_out_ = runtime_->buffer(CL_MEM_WRITE_ONLY, union_capacity_ * sizeof(cl_float4));
        }
        const cl_double4 box_min{{min_cm.x(), min_cm.y(), min_cm.z(), 0.0}};
        const cl_double4 box_max{{max_cm.x(), max_cm.y(), max_cm.z(), 0.0}};
        const std::size_t group = runtime_->work_group_size(place_within_, 64);
        for (std::size_t k = 0; k < parts.size(); ++k) {
          if (on_device[k] == nullptr) continue;
          const Pose& to_frame = parts[k].frame_from_cloud;
          int arg = 0;
          place_within_.setArg(arg++, on_device[k]->data_);
          place_within_.setArg(arg++, static_cast<cl_int>(parts[k].points_cm.size()));
          for (int r = 0; r < 3; ++r) {
            place_within_.setArg(arg++, cl_double4{{to_frame(r, 0), to_frame(r, 1), to_frame(r, 2), to_frame(r, 3)}});
          }
          place_within_.setArg(arg++, box_min);
          place_within_.setArg(arg++, box_max);
          place_within_.setArg(arg++, static_cast<cl_int>(offsets[k]));
          place_within_.setArg(arg++, union_out_);
          runtime_->launch(place_within_, round_up(parts[k].points_cm.size(), group), group);
        }
        std::vector<cl_float4> out(total);
        runtime_->queue().enqueueReadBuffer(union_out_, CL_TRUE, 0, total * sizeof(cl_float4), out.data());
        for (std::size_t k = 0; k < parts.size(); ++k) {
          if (on_device[k] == nullptr) continue;
          for (std::size_t i = 0; i < parts[k].points_cm.size(); ++i) {
            const cl_float4& q = out[offsets[k] + i];
            if (q.s[3] != 0.0f) placed[k].emplace_back(q.s[0], q.s[1], q.s[2]);
          }
        }
      } catch (...) {
        rethrow_as_device_error("OpenCL union of clouds");
      }
    }
    if (!on_host.empty()) {
      std::vector<UnionPart> rest;
      for (const std::size_t k : on_host) rest.push_back(parts[k]);
      std::vector<std::vector<Eigen::Vector3f>> host = placed_within_on_host(rest, min_cm, max_cm);
      for (std::size_t h = 0; h < on_host.size(); ++h) placed[on_host[h]] = std::move(host[h]);
    }
    return placed;
  }

  std::vector<Eigen::Vector3f> voxel_means_checked(std::span<const Eigen::Vector3f> points_cm, float voxel_cm,
                                                   std::span<const float> values,
                                                   std::vector<float>* value_means) override {
    // The host's where the device lacks double precision or 64-bit atomics, or a point is out of
    // the kernels' reach (status): the same bits either way.
    const auto on_host = [&] { return ComputeBackend::voxel_means_checked(points_cm, voxel_cm, values, value_means); };
    if (!runtime_->has_voxel_means() || points_cm.empty() || points_cm.size() >= (std::size_t{1} << 30)) return on_host();
    try {
      Runtime& runtime = *runtime_;
      auto& queue = runtime.queue();
      const auto n = static_cast<cl_uint>(points_cm.size());
      std::vector<cl_float4> host_points(n);
      for (cl_uint i = 0; i < n; ++i) host_points[i] = to_float4(points_cm[i].x(), points_cm[i].y(), points_cm[i].z(), 0.0f);
      const std::size_t table = std::bit_ceil(std::max<std::size_t>(64, 2 * std::size_t{n}));
      cl::Buffer points = runtime.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, n * sizeof(cl_float4), host_points.data());
      cl::Buffer keys = runtime.buffer(CL_MEM_READ_WRITE, table * sizeof(cl_ulong));
      cl::Buffer first = runtime.buffer(CL_MEM_READ_WRITE, table * sizeof(cl_uint));
      cl::Buffer counts = runtime.buffer(CL_MEM_READ_WRITE, table * sizeof(cl_uint));
      cl::Buffer slot_of = runtime.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_uint));
      cl::Buffer status = runtime.buffer(CL_MEM_READ_WRITE, sizeof(cl_int));
      queue.enqueueFillBuffer(keys, ~cl_ulong{0}, 0, table * sizeof(cl_ulong));
      queue.enqueueFillBuffer(first, ~cl_uint{0}, 0, table * sizeof(cl_uint));
      queue.enqueueFillBuffer(counts, cl_uint{0}, 0, table * sizeof(cl_uint));
      queue.enqueueFillBuffer(status, cl_int{0}, 0, sizeof(cl_int));
      int arg = 0;
      voxel_insert_.setArg(arg++, points);
      voxel_insert_.setArg(arg++, n);
      voxel_insert_.setArg(arg++, 1.0 / static_cast<double>(voxel_cm));  // as the host: cell = floor(v * inverse)
      voxel_insert_.setArg(arg++, keys);
      voxel_insert_.setArg(arg++, first);
      voxel_insert_.setArg(arg++, counts);
      voxel_insert_.setArg(arg++, static_cast<cl_uint>(table - 1));
      voxel_insert_.setArg(arg++, slot_of);
      voxel_insert_.setArg(arg++, status);
      const std::size_t insert_group = runtime.work_group_size(voxel_insert_, 64);
      runtime.launch(voxel_insert_, round_up(n, insert_group), insert_group);
      cl_int out_of_reach = 0;
      queue.enqueueReadBuffer(status, CL_TRUE, 0, sizeof(cl_int), &out_of_reach);
      if (out_of_reach != 0) return on_host();
      // Each point's (is first, cell count if first), prefix-summed per group; the groups' totals
      // added here in group order, as offsets for the next launch (same group size).
      const std::size_t group = runtime.work_group_size(voxel_scan_, 256);
      const std::size_t groups = round_up(n, group) / group;
      cl::Buffer prefix = runtime.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_uint2));
      cl::Buffer group_sums = runtime.buffer(CL_MEM_READ_WRITE, groups * sizeof(cl_uint2));
      arg = 0;
      voxel_scan_.setArg(arg++, slot_of);
      voxel_scan_.setArg(arg++, first);
      voxel_scan_.setArg(arg++, counts);
      voxel_scan_.setArg(arg++, n);
      voxel_scan_.setArg(arg++, prefix);
      voxel_scan_.setArg(arg++, group_sums);
      voxel_scan_.setArg(arg++, cl::Local(group * sizeof(cl_uint2)));
      runtime.launch(voxel_scan_, groups * group, group);
      std::vector<cl_uint2> offsets(groups);
      queue.enqueueReadBuffer(group_sums, CL_TRUE, 0, groups * sizeof(cl_uint2), offsets.data());
      cl_uint cells = 0, placed = 0;
      for (cl_uint2& offset : offsets) {
        const cl_uint2 total = offset;
        offset = cl_uint2{{cells, placed}};
        cells += total.s[0];
        placed += total.s[1];
      }
      if (placed != n) throw DeviceError("voxel means: the cells hold " + std::to_string(placed) + " of " + std::to_string(n) + " points");
      queue.enqueueWriteBuffer(group_sums, CL_TRUE, 0, groups * sizeof(cl_uint2), offsets.data());
      cl::Buffer cell_of_slot = runtime.buffer(CL_MEM_READ_WRITE, table * sizeof(cl_uint));
      cl::Buffer cell_start = runtime.buffer(CL_MEM_READ_WRITE, cells * sizeof(cl_uint));
      cl::Buffer cell_count = runtime.buffer(CL_MEM_READ_WRITE, cells * sizeof(cl_uint));
      arg = 0;
      voxel_cells_.setArg(arg++, slot_of);
      voxel_cells_.setArg(arg++, first);
      voxel_cells_.setArg(arg++, counts);
      voxel_cells_.setArg(arg++, n);
      voxel_cells_.setArg(arg++, prefix);
      voxel_cells_.setArg(arg++, group_sums);
      voxel_cells_.setArg(arg++, cell_of_slot);
      voxel_cells_.setArg(arg++, cell_start);
      voxel_cells_.setArg(arg++, cell_count);
      runtime.launch(voxel_cells_, groups * group, group);
      cl::Buffer filled = runtime.buffer(CL_MEM_READ_WRITE, cells * sizeof(cl_uint));
      cl::Buffer member_list = runtime.buffer(CL_MEM_READ_WRITE, n * sizeof(cl_uint));
      queue.enqueueFillBuffer(filled, cl_uint{0}, 0, cells * sizeof(cl_uint));
      arg = 0;
      voxel_members_.setArg(arg++, slot_of);
      voxel_members_.setArg(arg++, n);
      voxel_members_.setArg(arg++, cell_of_slot);
      voxel_members_.setArg(arg++, cell_start);
      voxel_members_.setArg(arg++, filled);
      voxel_members_.setArg(arg++, member_list);
      runtime.launch(voxel_members_, round_up(n, insert_group), insert_group);
      const bool with_values = value_means != nullptr;
      cl::Buffer value_buffer =
          with_values ? runtime.buffer(CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, n * sizeof(float), const_cast<float*>(values.data()))
                      : runtime.buffer(CL_MEM_READ_ONLY, sizeof(float));
      cl::Buffer means = runtime.buffer(CL_MEM_WRITE_ONLY, cells * sizeof(cl_float4));
      arg = 0;
      voxel_sum_.setArg(arg++, points);
      voxel_sum_.setArg(arg++, value_buffer);
      voxel_sum_.setArg(arg++, static_cast<cl_int>(with_values ? 1 : 0));
      voxel_sum_.setArg(arg++, cells);
      voxel_sum_.setArg(arg++, cell_start);
      voxel_sum_.setArg(arg++, cell_count);
      voxel_sum_.setArg(arg++, member_list);
      voxel_sum_.setArg(arg++, means);
      const std::size_t sum_group = runtime.work_group_size(voxel_sum_, 64);
      runtime.launch(voxel_sum_, round_up(cells, sum_group), sum_group);
      std::vector<cl_float4> host_means(cells);
      queue.enqueueReadBuffer(means, CL_TRUE, 0, cells * sizeof(cl_float4), host_means.data());
      std::vector<Eigen::Vector3f> out(cells);
      for (cl_uint c = 0; c < cells; ++c) out[c] = Eigen::Vector3f(host_means[c].s[0], host_means[c].s[1], host_means[c].s[2]);
      if (with_values) {
        value_means->resize(cells);
        for (cl_uint c = 0; c < cells; ++c) (*value_means)[c] = host_means[c].s[3];
      }
      return out;
    } catch (const DeviceError&) {
      throw;
    } catch (...) {
      rethrow_as_device_error("OpenCL voxel means");
    }
  }

 private:
  static const OpenClPreparedCloud& as_device(const PreparedCloud& cloud) {
    const auto* device_cloud = dynamic_cast<const OpenClPreparedCloud*>(&cloud);
    if (!device_cloud) throw std::invalid_argument("cloud was not prepared by the OpenCL backend");
    return *device_cloud;
  }

  /// Launches the search for every model; false when no model could pair anything (all empty).
  bool search(const OpenClPreparedCloud& cloud, cl_int n, std::span<const ModelPlacement> models, SearchMethod method,
              const PairingSettings& settings) {
    require_exact_search_for_skips(models, method);
    reserve_scratch(static_cast<std::size_t>(n));
    const float max_squared = settings.max_pair_dist_cm * settings.max_pair_dist_cm;
    bool first = true;
    for (std::size_t k = 0; k < models.size(); ++k) {
      const auto& model = as_device(*models[k].model);
      const auto& tree = model.tree();
      if (tree.empty()) continue;
      const auto to_model = rows_of(models[k].model_from_data);
      const auto to_data = rows_of(rigid_inverse(models[k].model_from_data));
      const cl_float4 lo = to_float4(tree.bounds_min().x(), tree.bounds_min().y(), tree.bounds_min().z(), 0.0f);
      const cl_float4 hi = to_float4(tree.bounds_max().x(), tree.bounds_max().y(), tree.bounds_max().z(), 0.0f);
      const cl_int model_id = static_cast<cl_int>(k);
      const cl_int first_model = first ? 1 : 0;
      if (method == SearchMethod::kBruteForce) {
        cl::Kernel& kernel = nearest_brute_force_;
        int arg = 0;
        kernel.setArg(arg++, cloud.data_);
        kernel.setArg(arg++, n);
        kernel.setArg(arg++, model.tree_points_);
        kernel.setArg(arg++, static_cast<cl_int>(tree.size()));
        kernel.setArg(arg++, lo);
        kernel.setArg(arg++, hi);
        for (const auto& row : to_model) kernel.setArg(arg++, row);
        for (const auto& row : to_data) kernel.setArg(arg++, row);
        kernel.setArg(arg++, max_squared);
        kernel.setArg(arg++, model_id);
        kernel.setArg(arg++, first_model);
        kernel.setArg(arg++, best_pair_);
        kernel.setArg(arg++, best_ref_);
        runtime_->launch(kernel, round_up(static_cast<std::size_t>(n), kBruteTile), kBruteTile);
      } else {
        cl::Kernel& kernel = nearest_in_tree_;
        int arg = 0;
        kernel.setArg(arg++, cloud.data_);
        kernel.setArg(arg++, n);
        kernel.setArg(arg++, model.nodes_);
        kernel.setArg(arg++, model.tree_points_);
        kernel.setArg(arg++, model.leaf_means_);
        kernel.setArg(arg++, lo);
        kernel.setArg(arg++, hi);
        for (const auto& row : to_model) kernel.setArg(arg++, row);
        for (const auto& row : to_data) kernel.setArg(arg++, row);
        kernel.setArg(arg++, static_cast<cl_int>(method == SearchMethod::kApproximate ? 1 : 0));
        kernel.setArg(arg++, static_cast<cl_int>(models[k].skip.first));
        kernel.setArg(arg++, static_cast<cl_int>(models[k].skip.count));
        kernel.setArg(arg++, max_squared);
        kernel.setArg(arg++, model_id);
        kernel.setArg(arg++, first_model);
        kernel.setArg(arg++, best_pair_);
        kernel.setArg(arg++, best_ref_);
        const std::size_t group = runtime_->work_group_size(kernel, kSearchGroupSize);
        runtime_->launch(kernel, round_up(static_cast<std::size_t>(n), group), group);
      }
      first = false;
    }
    return !first;
  }

  /// The per-query results of a search (closest pair so far, and its reference), held by the
  /// backend, not the clouds: prepared clouds stay immutable. Grown, never shrunk.
  void reserve_scratch(std::size_t n) {
    if (scratch_capacity_ >= n) return;
    best_pair_ = runtime_->buffer(CL_MEM_READ_WRITE, n * sizeof(cl_float4));
    best_ref_ = runtime_->buffer(CL_MEM_READ_WRITE, n * sizeof(cl_int2));
    scratch_capacity_ = n;
  }

  std::shared_ptr<Runtime> runtime_;
  cl::Kernel nearest_in_tree_, nearest_brute_force_, pair_sums_, filter_slices_;
  cl::Buffer best_pair_, best_ref_;
  std::size_t scratch_capacity_ = 0;
  std::size_t reduction_group_size_ = kReductionGroupSize;
  cl::Buffer partials_;
  cl::Kernel pair_sums_blocks_;  ///< only on devices with cl_khr_fp64
  cl::Kernel place_within_;      ///< kernels/union.cl, only on devices with cl_khr_fp64
  cl::Buffer union_out_;         ///< place_within's output, grown as unions grow
  std::size_t union_capacity_ = 0;
  /// kernels/voxel_means.cl, only where Runtime::has_voxel_means.
  cl::Kernel voxel_insert_, voxel_scan_, voxel_cells_, voxel_members_, voxel_sum_;
  cl::Buffer block_partials_;
  std::size_t block_partials_count_ = 0;
};

}  // namespace

std::unique_ptr<ComputeBackend> make_opencl_backend(const OpenClOptions& options) {
  try {
    return std::make_unique<OpenClBackend>(Runtime::create(options));
  } catch (const DeviceError&) {
    throw;
  } catch (const std::exception& e) {
    throw DeviceError(e.what());
  }
}

}  // namespace minemap::opencl
