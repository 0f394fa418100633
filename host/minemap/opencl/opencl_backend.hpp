#pragma once
// The OpenCL compute backend (target minemap::opencl, built where CMake finds OpenCL; internal:
// users reach it through make_backend, minemap/backend/make_backend.hpp, where its options are).
// This header includes no OpenCL header: only the .cpp files of this folder do.
//
// Device choice: OpenClOptions::device (a substring of "platform / device", case-insensitive)
// wins; otherwise the first available GPU, preferring a discrete one (no host-unified memory) with
// the most compute units; otherwise, where allowed, a CPU device (PoCL).
//
// Faults. Every OpenCL call goes through the C++ bindings with exceptions on, so a failing status
// becomes cl::Error, which the backend turns into a BackendError naming the call and the status:
//   * no platform, no device, kernel build failure (setup): make_opencl_backend throws; make_backend
//     (host/minemap/backend/make_backend.hpp) then picks the CPU for `auto` and fails for `opencl`.
//   * a failing launch, allocation or transfer once mapping has begun: map_survey matches the whole
//     survey again on a fresh CPU backend, with one note, so the poses are the CPU run's.
// OpenClOptions::fault makes one fault happen through the path a real one takes (tests):
//   build       the compiler gets the kernel source with an invalid declaration appended, so the
//               real clBuildProgram fails (CL_BUILD_PROGRAM_FAILURE) and its build log is reported;
//   launch:N    the N-th kernel launch of this backend (search, reduction or slice filter; N >= 1)
//   N           fails as if clEnqueueNDRangeKernel returned CL_OUT_OF_RESOURCES;
//   alloc:N     the N-th device buffer this backend creates fails as if clCreateBuffer returned
//               CL_MEM_OBJECT_ALLOCATION_FAILURE (device memory exhausted).
#include <memory>
#include <string>

#include "minemap/backend/make_backend.hpp"

namespace minemap::opencl {

/// The OpenCL backend on the device `options` choose: its context, queue, compiled kernels and
/// scratch buffers are its own (two backends share nothing). Throws BackendError saying why when
/// no device fits or the kernels do not build.
std::unique_ptr<ComputeBackend> make_opencl_backend(const OpenClOptions& options);

}  // namespace minemap::opencl
