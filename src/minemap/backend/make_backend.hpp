#pragma once
// Making a compute backend from the user's choice: the composition root's helper (the CLI, the
// tests and the benchmarks use it; the algorithm never does, it is handed a backend). Target
// minemap::backends, defined in host/minemap/backends.cpp, the one file that knows which backends
// this build has (the OpenCL one only where minemap was built with it).
#include <memory>
#include <string>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/core/name_table.hpp"

namespace minemap {
namespace opencl {

/// A fault to inject into the OpenCL backend (host/minemap/opencl/opencl_backend.hpp says how each
/// one takes the path of a real fault). Tests only.
struct InjectedFault {
  enum class Kind { kNone, kBuild, kLaunch, kAlloc };
  Kind kind = Kind::kNone;
  long at = 0;  ///< launch, alloc: the 1-based call that fails

  /// Parses "build", "launch:N", "alloc:N" or "N" (empty: none); throws BackendError naming the
  /// text when it is not understood.
  static InjectedFault parse(const std::string& text);
};

/// How to set up the OpenCL backend. Thread-safety: a plain value.
struct OpenClOptions {
  std::string device;             ///< substring of "platform / device"; empty: the best GPU
  bool allow_cpu_device = false;  ///< accept a CPU device (PoCL) when no GPU is found
  /// Make the ICP sums in double where the device has cl_khr_fp64 (bit-identical to the CPU); off:
  /// the float-sum path a device without double precision takes (tests run it on PoCL).
  bool fp64 = true;
  InjectedFault fault;  ///< tests only
};

}  // namespace opencl

enum class Backend {
  kAuto,    ///< OpenCL on a GPU when one works, else the CPU (PoCL on a 2-core CPU is slower than TBB)
  kCpu,     ///< TBB
  kOpenCl,  ///< OpenCL (PoCL included), or an error saying why not
};
inline constexpr std::array<EnumName<Backend>, 3> kBackendNames{
    {{Backend::kAuto, "auto"}, {Backend::kCpu, "cpu"}, {Backend::kOpenCl, "opencl"}}};
const char* to_string(Backend backend);
Backend parse_backend(const std::string& text);  ///< a name of kBackendNames

/// Everything that decides which backend runs. Thread-safety: a plain value.
struct BackendOptions {
  Backend kind = Backend::kAuto;
  bool opencl_disabled = false;  ///< never try OpenCL: auto uses the CPU, opencl is an error
  opencl::OpenClOptions opencl;  ///< device choice, fp64, fault injection; allow_cpu_device follows `kind`
};

/// A backend and how it was chosen, in one line for the user ("OpenCL backend: <device>",
/// "CPU backend (TBB): no OpenCL GPU found (...)").
struct BackendChoice {
  std::unique_ptr<ComputeBackend> backend;
  std::string message;
};

/// kCpu: the CPU backend. kOpenCl: the OpenCL backend or BackendError saying why not (no device, a
/// build failure, or a minemap built without OpenCL). kAuto: OpenCL on a GPU (or the device named)
/// when it works, else the CPU backend, with the reason in `message`.
BackendChoice make_backend(const BackendOptions& options);

/// Options from the environment, for composition roots only (nothing else in minemap reads it):
///   MINEMAP_OPENCL=off            opencl_disabled
///   MINEMAP_OPENCL_DEVICE=NAME    opencl.device
///   MINEMAP_OPENCL_FP64=off       opencl.fp64 = false (the float-sum path, for tests)
///   MINEMAP_OPENCL_INJECT_FAULT   opencl.fault (opencl_backend.hpp); BackendError when not understood
BackendOptions backend_options_from_environment(Backend kind);

/// Whether this build has the OpenCL backend.
bool built_with_opencl();

}  // namespace minemap
