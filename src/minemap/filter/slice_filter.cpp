// The dispatch point of the slice filter between the CPU reference and the OpenCL kernel.
#include "minemap/filter/slice_filter.hpp"

#include "minemap/opencl/opencl_backend.hpp"
#include "minemap/search/pairing.hpp"

namespace minemap {

SliceFilterResult filter_scan(const Scan& scan, const SliceFilterSettings& settings, Backend backend,
                              std::string* note) {
  settings.validate();
  if (!scan.has_slices()) {
    if (note) *note = "scan " + scan.name + " has no slice structure: slice filter skipped";
    return filter_scan_cpu(scan, settings);
  }
  if (backend != Backend::kCpu) {
    std::string why_not;
    auto result = opencl::filter_scan_opencl(scan, settings, backend == Backend::kOpenCl, &why_not);
    if (result) return std::move(*result);
    if (note) *note = "slice filter on the CPU: " + why_not;
  }
  return filter_scan_cpu(scan, settings);
}

}  // namespace minemap
