// The slice filter on an OpenCL device: one launch filters all kept slices of a scan, one
// work-item per slice; each slice writes into its own input range (output never exceeds input).
// A device that fails here (allocation, launch, transfer) throws DeviceError: the survey matcher
// then matches the whole survey on the CPU, so no run mixes filter results of both backends.
#include <vector>

#include "minemap/opencl/opencl_backend.hpp"
#include "minemap/opencl/runtime.hpp"

namespace minemap::opencl {

std::optional<SliceFilterResult> filter_scan_opencl(const Scan& scan, const SliceFilterSettings& settings,
                                                    bool allow_cpu_device, std::string* why_not) {
  settings.validate();
  auto runtime = Runtime::get(allow_cpu_device, why_not);
  if (!runtime) return std::nullopt;
  if (!scan.has_slices()) return unfiltered_result(scan, "opencl");
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
    static thread_local std::weak_ptr<Runtime> kernel_owner;
    static thread_local cl::Kernel kernel;
    if (kernel_owner.lock() != runtime) {
      kernel = cl::Kernel(runtime->program(), "filter_slices");
      kernel_owner = runtime;
    }
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

}  // namespace minemap::opencl
