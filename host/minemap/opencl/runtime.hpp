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
//
// Faults. Every OpenCL call goes through the C++ bindings with exceptions on, so a failing status
// becomes cl::Error, which the backends turn into DeviceError (a BackendError). What a failure does:
//   * no platform, no device, kernel build failure (setup): `--backend auto` maps on the CPU and
//     says why in its one "backend:" line; `--backend opencl` stops with exit code 6.
//   * a failing launch, allocation or transfer once mapping has begun (pairing or slice filter):
//     map_survey drops the device and matches the whole survey again on the CPU, with one note, so
//     the poses are the CPU run's (`--backend opencl` included: the user gets a map, not an error).
// Test hook MINEMAP_OPENCL_INJECT_FAULT makes one fault happen through the path a real one takes:
//   build       the compiler gets the kernel source with an invalid declaration appended, so the
//               real clBuildProgram fails (CL_BUILD_PROGRAM_FAILURE) and its build log is reported;
//               read when the runtime starts (once per process).
//   launch:N    the N-th kernel launch (search, reduction or slice filter; N >= 1) fails as if
//   N           clEnqueueNDRangeKernel returned CL_OUT_OF_RESOURCES.
//   alloc:N     the N-th device buffer creation fails as if clCreateBuffer returned
//               CL_MEM_OBJECT_ALLOCATION_FAILURE (device memory exhausted).
// launch and alloc count from the creation of the latest pairing backend (which re-reads the
// variable), or from the runtime's start. Any other value makes OpenCL unusable, saying why.
#include <CL/opencl.hpp>
#include <atomic>
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

/// The fault MINEMAP_OPENCL_INJECT_FAULT asks for (see the file comment).
struct InjectedFault {
  enum class Kind { kNone, kBuild, kLaunch, kAlloc };
  Kind kind = Kind::kNone;
  long at = 0;  ///< launch, alloc: the 1-based call that fails

  /// Parses the variable's value (nullptr or empty: none); throws DeviceError when not understood.
  static InjectedFault parse(const char* text);
  static InjectedFault from_environment();
};

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
  /// The device does double precision (cl_khr_fp64): the ICP sums are then made exactly as the CPU
  /// backend makes them (kernel pair_sums_blocks), and both backends give the same bits.
  bool has_fp64() const { return has_fp64_; }

  /// clCreateBuffer; every device buffer is made here, so an injected allocation fault takes the
  /// path of a real one (cl::Error with CL_MEM_OBJECT_ALLOCATION_FAILURE).
  cl::Buffer buffer(cl_mem_flags flags, std::size_t bytes, void* host = nullptr);
  /// clEnqueueNDRangeKernel on the runtime's queue; every launch goes through here (see `buffer`).
  void launch(const cl::Kernel& kernel, std::size_t global, std::size_t local);
  /// Re-reads MINEMAP_OPENCL_INJECT_FAULT and restarts its counts (a new pairing backend does this).
  void rearm_fault_injection();

  Runtime(cl::Device device, bool is_gpu);

 private:
  cl::Device device_;
  cl::Context context_;
  cl::CommandQueue queue_;
  cl::Program program_;
  std::string description_;
  bool is_gpu_ = false;
  std::size_t max_alloc_bytes_ = 0;
  bool has_fp64_ = false;
  std::atomic<InjectedFault::Kind> fault_kind_{InjectedFault::Kind::kNone};
  std::atomic<long> fault_at_{0};
  std::atomic<long> launches_{0};
  std::atomic<long> allocations_{0};
};

/// Rounds `n` up to a multiple of `multiple`.
inline std::size_t round_up(std::size_t n, std::size_t multiple) { return (n + multiple - 1) / multiple * multiple; }

}  // namespace minemap::opencl
