#pragma once
// Internal to the OpenCL backend (not installed): one device's context, queue and compiled program,
// and the names of OpenCL's errors. Each OpenClBackend owns one Runtime; nothing here is static
// and nothing reads the environment (OpenClOptions carries every choice).
//
// Thread-safety: a runtime's queue must be used by one thread at a time (its backend is
// single-threaded by contract).
#include <CL/opencl.hpp>
#include <memory>
#include <stdexcept>
#include <string>

#include "minemap/opencl/opencl_backend.hpp"

namespace minemap::opencl {

/// An OpenCL failure, with the call and the error's name ("clEnqueueNDRangeKernel: CL_OUT_OF_RESOURCES").
class DeviceError : public BackendError {
 public:
  using BackendError::BackendError;
};

const char* error_name(cl_int code);

/// Rethrows cl::Error (and cl::BuildError, with its log) as DeviceError naming `what`.
[[noreturn]] void rethrow_as_device_error(const std::string& what);

class Runtime {
 public:
  /// A runtime on the device `options` choose (opencl_backend.hpp), its program built; throws
  /// DeviceError saying why when no device fits or the build fails.
  static std::shared_ptr<Runtime> create(const OpenClOptions& options);

  cl::Context& context() { return context_; }
  cl::CommandQueue& queue() { return queue_; }
  cl::Device& device() { return device_; }
  const cl::Program& program() const { return program_; }
  const std::string& description() const { return description_; }
  bool is_gpu() const { return is_gpu_; }
  /// Largest power of two <= min(wanted, the kernel's and the device's work-group limits).
  std::size_t work_group_size(const cl::Kernel& kernel, std::size_t wanted) const;
  std::size_t max_alloc_bytes() const { return max_alloc_bytes_; }
  /// The device does double precision (cl_khr_fp64): the ICP sums are then made exactly as the CPU
  /// backend makes them (kernel pair_sums_blocks), and both backends give the same bits.
  bool has_fp64() const { return has_fp64_; }
  /// The device does double precision and 64-bit atomics (cl_khr_int64_base_atomics): the voxel
  /// means run there (kernels/voxel_means.cl), else on the host; the same bits either way.
  bool has_voxel_means() const { return has_voxel_means_; }

  /// clCreateBuffer; every device buffer is made here, so an injected allocation fault takes the
  /// path of a real one (cl::Error with CL_MEM_OBJECT_ALLOCATION_FAILURE).
  cl::Buffer buffer(cl_mem_flags flags, std::size_t bytes, void* host = nullptr);
  /// clEnqueueNDRangeKernel on the runtime's queue; every launch goes through here (see `buffer`).
  void launch(const cl::Kernel& kernel, std::size_t global, std::size_t local);
  Runtime(cl::Device device, bool is_gpu, const OpenClOptions& options);

 private:
  cl::Device device_;
  cl::Context context_;
  cl::CommandQueue queue_;
  cl::Program program_;
  std::string description_;
  bool is_gpu_ = false;
  std::size_t max_alloc_bytes_ = 0;
  bool has_fp64_ = false;
  bool has_voxel_means_ = false;
  InjectedFault fault_;
  long launches_ = 0;
  long allocations_ = 0;
};

/// Rounds `n` up to a multiple of `multiple`.
inline std::size_t round_up(std::size_t n, std::size_t multiple) { return (n + multiple - 1) / multiple * multiple; }

}  // namespace minemap::opencl
