#pragma once
// Internal (not installed): the CPU slice filter without the settings check, for CpuBackend, whose
// caller (ComputeBackend::filter_slices) has checked them.
#include "minemap/filter/slice_filter.hpp"

namespace minemap::detail {

/// The slice filter of a scan with slices; `settings` must be valid.
SliceFilterResult filter_slices_cpu(const Scan& scan, const SliceFilterSettings& settings);

}  // namespace minemap::detail
