#pragma once
// The OpenCL entry points seen by the rest of minemap. This header includes no OpenCL headers:
// only files under host/ do, so src/ compiles without them.
#include <memory>
#include <optional>
#include <string>

#include "minemap/filter/slice_filter.hpp"
#include "minemap/search/pairing.hpp"

namespace minemap::opencl {

/// Creates the OpenCL pairing backend, or returns nullptr with the reason in `why_not` (no platform,
/// no device, kernel build failure, ...). Later device failures throw DeviceError (a BackendError).
/// `allow_cpu_device`: accept a CPU OpenCL device (PoCL) when no GPU is found; `auto` mode passes
/// false because TBB beats PoCL on the same cores.
std::unique_ptr<PairingBackend> make_opencl_pairing_backend(bool allow_cpu_device, std::string* why_not);

/// Runs the slice filter on the OpenCL device. Returns nullopt with the reason in `why_not` when
/// no device is usable (the caller uses the CPU). A device that fails during the run (allocation,
/// launch, transfer) throws DeviceError, a BackendError: map_survey then matches the whole survey
/// on the CPU. Faults and the injection hook MINEMAP_OPENCL_INJECT_FAULT: runtime.hpp.
std::optional<SliceFilterResult> filter_scan_opencl(const Scan& scan, const SliceFilterSettings& settings,
                                                    bool allow_cpu_device, std::string* why_not);

/// One line naming platform, device and driver of the device minemap would use, or why none.
std::string describe_device(bool allow_cpu_device);

}  // namespace minemap::opencl
