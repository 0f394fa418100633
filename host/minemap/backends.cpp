// The backend factory (minemap/backend/make_backend.hpp): the one file that knows which backends
// this build has.
#include "minemap/backend/make_backend.hpp"
#include "minemap/opencl/opencl_backend.hpp"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <stdexcept>

namespace minemap {
namespace {

std::string lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::tolower(c); });
  return text;
}

}  // namespace

const char* to_string(Backend backend) { return name_in(kBackendNames, backend); }

Backend parse_backend(const std::string& text) { return parse_named(kBackendNames, text, "backend"); }

bool built_with_opencl() { return MINEMAP_WITH_OPENCL != 0; }

// Here rather than with the OpenCL backend: the composition root parses the option even in a
// build without OpenCL (where asking for a fault is then an error of its own).
opencl::InjectedFault opencl::InjectedFault::parse(const std::string& text) {
  InjectedFault fault;
  if (text.empty()) return fault;
  const std::string value = lower(text);
  std::string count = value;
  if (value == "build") {
    fault.kind = Kind::kBuild;
    return fault;
  }
  if (value.rfind("launch:", 0) == 0) {
    fault.kind = Kind::kLaunch;
    count = value.substr(7);
  } else if (value.rfind("alloc:", 0) == 0) {
    fault.kind = Kind::kAlloc;
    count = value.substr(6);
  } else {
    fault.kind = Kind::kLaunch;  // a plain number: the launch fault, as first defined
  }
  const bool digits = !count.empty() && count.size() <= 9 &&
                      std::all_of(count.begin(), count.end(), [](unsigned char c) { return std::isdigit(c) != 0; });
  fault.at = digits ? std::stol(count) : 0;
  if (fault.at < 1) {
    throw BackendError("MINEMAP_OPENCL_INJECT_FAULT='" + text +
                       "' is not understood (expected build, launch:N, alloc:N or N, with N >= 1)");
  }
  return fault;
}


namespace {

/// The OpenCL backend, or BackendError saying why not.
std::unique_ptr<ComputeBackend> opencl_backend(const BackendOptions& options) {
  if (options.opencl_disabled) throw BackendError("OpenCL disabled by MINEMAP_OPENCL=off");
#if MINEMAP_WITH_OPENCL
  opencl::OpenClOptions opencl = options.opencl;
  // auto insists on a GPU (or the device the user named); opencl takes a CPU device too.
  opencl.allow_cpu_device = options.kind == Backend::kOpenCl;
  return opencl::make_opencl_backend(opencl);
#else
  throw BackendError("minemap was built without OpenCL (CMake found no OpenCL headers and ICD loader)");
#endif
}

}  // namespace

BackendChoice make_backend(const BackendOptions& options) {
  BackendChoice choice;
  if (options.kind == Backend::kCpu) {
    choice.backend = make_cpu_backend();
    choice.message = "CPU backend (TBB) as requested";
    return choice;
  }
  try {
    choice.backend = opencl_backend(options);
    choice.message = "OpenCL backend: " + choice.backend->device_description();
  } catch (const BackendError& e) {
    if (options.kind == Backend::kOpenCl) throw BackendError(std::string("OpenCL backend unavailable: ") + e.what());
    choice.backend = make_cpu_backend();
    choice.message = std::string("CPU backend (TBB): ") + e.what();
  }
  return choice;
}

BackendOptions backend_options_from_environment(Backend kind) {
  BackendOptions options;
  options.kind = kind;
  if (const char* v = std::getenv("MINEMAP_OPENCL"); v && lower(v) == "off") options.opencl_disabled = true;
  if (const char* v = std::getenv("MINEMAP_OPENCL_DEVICE"); v && *v) options.opencl.device = v;
  if (const char* v = std::getenv("MINEMAP_OPENCL_FP64"); v && lower(v) == "off") options.opencl.fp64 = false;
  if (const char* v = std::getenv("MINEMAP_OPENCL_INJECT_FAULT"); v && *v && kind != Backend::kCpu) {
    options.opencl.fault = opencl::InjectedFault::parse(v);
  }
  return options;
}

}  // namespace minemap
