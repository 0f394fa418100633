#pragma once
// OpenCL runtime: picks one device per process, builds the embedded kernels once (per device),
// and names every error. Only host/ includes this header.
//
// Device choice: MINEMAP_OPENCL_DEVICE (substring of "platform / device", case-insensitive) wins;
// otherwise the first available GPU, preferring a discrete one (no host-unified memory) with the
// most compute units; otherwise, where allowed, a CPU device (PoCL). MINEMAP_OPENCL=off disables
// OpenCL altogether (the documented way to force the CPU path in scripts).
//
// Thread-safety: `Runtime::get` is safe to call from any thread; the returned runtime's queue must
// be used by one thread at a time (the pairing backend is single-threaded by contract).
#include <CL/opencl.hpp>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>

#include "minemap/search/pairing.hpp"

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
  /// The process-wide runtime, or nullptr with the reason in `why_not`.
  static std::shared_ptr<Runtime> get(bool allow_cpu_device, std::string* why_not);

  cl::Context& context() { return context_; }
  cl::CommandQueue& queue() { return queue_; }
  cl::Device& device() { return device_; }
  const cl::Program& program() const { return program_; }
  const std::string& description() const { return description_; }
  bool is_gpu() const { return is_gpu_; }
  /// Largest power of two <= min(wanted, the kernel's and the device's work-group limits).
  std::size_t work_group_size(const cl::Kernel& kernel, std::size_t wanted) const;
  std::size_t max_alloc_bytes() const { return max_alloc_bytes_; }

  Runtime(cl::Device device, bool is_gpu);

 private:
  cl::Device device_;
  cl::Context context_;
  cl::CommandQueue queue_;
  cl::Program program_;
  std::string description_;
  bool is_gpu_ = false;
  std::size_t max_alloc_bytes_ = 0;
};

/// Rounds `n` up to a multiple of `multiple`.
inline std::size_t round_up(std::size_t n, std::size_t multiple) { return (n + multiple - 1) / multiple * multiple; }

}  // namespace minemap::opencl
