#include "minemap/opencl/runtime.hpp"

#include <algorithm>
#include <cctype>
#include <tuple>
#include <sstream>
#include <vector>

#include "minemap/kernels_embedded.hpp"

namespace minemap::opencl {
namespace {

std::string lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::tolower(c); });
  return text;
}

std::string kernel_source() {
  std::string source;
  for (const char* chunk : kernels::kSourceChunks) source += chunk;
  return source;
}

/// What MINEMAP_OPENCL_INJECT_FAULT=build appends: a declaration no OpenCL C compiler accepts.
constexpr const char* kInjectedBuildFault =
    "\n// MINEMAP_OPENCL_INJECT_FAULT=build\n__kernel void minemap_injected_build_fault(void) { not_opencl_c; }\n";

/// A build log cut to its first lines: the first error is what matters, and a log of warnings
/// must not bury the rest of the output.
std::string shortened_log(const std::string& log) {
  constexpr std::size_t kMaxLines = 30;
  std::istringstream in(log);
  std::string line, out;
  std::size_t lines = 0, dropped = 0;
  while (std::getline(in, line)) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (lines++ < kMaxLines) {
      out += "\n  " + line;
    } else {
      ++dropped;
    }
  }
  if (dropped > 0) out += "\n  ... (" + std::to_string(dropped) + " more lines)";
  return out;
}

struct Candidate {
  cl::Device device;
  std::string label;  // "platform / device"
  bool is_gpu = false;
  bool discrete = false;
  cl_uint compute_units = 0;
};

std::vector<Candidate> list_devices() {
  std::vector<Candidate> candidates;
  std::vector<cl::Platform> platforms;
  cl::Platform::get(&platforms);
  for (auto& platform : platforms) {
    std::vector<cl::Device> devices;
    try {
      platform.getDevices(CL_DEVICE_TYPE_ALL, &devices);
    } catch (const cl::Error&) {
      continue;  // a platform with no devices (CL_DEVICE_NOT_FOUND)
    }
    for (auto& device : devices) {
      if (!device.getInfo<CL_DEVICE_AVAILABLE>() || !device.getInfo<CL_DEVICE_COMPILER_AVAILABLE>()) continue;
      Candidate c;
      c.device = device;
      c.label = platform.getInfo<CL_PLATFORM_NAME>() + " / " + device.getInfo<CL_DEVICE_NAME>();
      c.is_gpu = (device.getInfo<CL_DEVICE_TYPE>() & CL_DEVICE_TYPE_GPU) != 0;
      c.discrete = !device.getInfo<CL_DEVICE_HOST_UNIFIED_MEMORY>();
      c.compute_units = device.getInfo<CL_DEVICE_MAX_COMPUTE_UNITS>();
      candidates.push_back(std::move(c));
    }
  }
  return candidates;
}

/// The device `options` choose; throws DeviceError saying why none fits.
Candidate pick_device(const OpenClOptions& options) {
  std::vector<Candidate> candidates;
  try {
    candidates = list_devices();
  } catch (const cl::Error& e) {
    if (e.err() == CL_PLATFORM_NOT_FOUND_KHR) {
      throw DeviceError(std::string("no OpenCL platform found (") + e.what() + ": " + error_name(e.err()) +
                        "); install an ICD such as pocl-opencl-icd or a GPU driver");
    }
    throw DeviceError(std::string("listing the OpenCL devices failed (") + e.what() + ": " + error_name(e.err()) + ")");
  }
  if (candidates.empty()) throw DeviceError("no available OpenCL device with a compiler");
  if (!options.device.empty()) {
    for (auto& c : candidates) {
      if (lower(c.label).find(lower(options.device)) != std::string::npos) return c;
    }
    throw DeviceError("OpenCL device '" + options.device + "' matches no device");
  }
  auto rank = [](const Candidate& c) { return std::make_tuple(c.is_gpu, c.discrete, c.compute_units); };
  const Candidate best = *std::max_element(candidates.begin(), candidates.end(),
                                           [&](const Candidate& a, const Candidate& b) { return rank(a) < rank(b); });
  if (!best.is_gpu && !options.allow_cpu_device) {
    throw DeviceError("no OpenCL GPU found (only " + best.label + "; use --backend opencl to run on it)");
  }
  return best;
}

}  // namespace

const char* error_name(cl_int code) {
  switch (code) {
#define MM_CASE(x) \
  case x: return #x;
    MM_CASE(CL_SUCCESS) MM_CASE(CL_DEVICE_NOT_FOUND) MM_CASE(CL_DEVICE_NOT_AVAILABLE)
    MM_CASE(CL_COMPILER_NOT_AVAILABLE) MM_CASE(CL_MEM_OBJECT_ALLOCATION_FAILURE) MM_CASE(CL_OUT_OF_RESOURCES)
    MM_CASE(CL_OUT_OF_HOST_MEMORY) MM_CASE(CL_BUILD_PROGRAM_FAILURE) MM_CASE(CL_INVALID_VALUE)
    MM_CASE(CL_INVALID_DEVICE) MM_CASE(CL_INVALID_CONTEXT) MM_CASE(CL_INVALID_COMMAND_QUEUE)
    MM_CASE(CL_INVALID_MEM_OBJECT) MM_CASE(CL_INVALID_BUILD_OPTIONS) MM_CASE(CL_INVALID_PROGRAM)
    MM_CASE(CL_INVALID_PROGRAM_EXECUTABLE) MM_CASE(CL_INVALID_KERNEL_NAME) MM_CASE(CL_INVALID_KERNEL)
    MM_CASE(CL_INVALID_ARG_INDEX) MM_CASE(CL_INVALID_ARG_VALUE) MM_CASE(CL_INVALID_ARG_SIZE)
    MM_CASE(CL_INVALID_KERNEL_ARGS) MM_CASE(CL_INVALID_WORK_DIMENSION) MM_CASE(CL_INVALID_WORK_GROUP_SIZE)
    MM_CASE(CL_INVALID_WORK_ITEM_SIZE) MM_CASE(CL_INVALID_GLOBAL_OFFSET) MM_CASE(CL_INVALID_EVENT_WAIT_LIST)
    MM_CASE(CL_INVALID_OPERATION) MM_CASE(CL_INVALID_BUFFER_SIZE) MM_CASE(CL_INVALID_GLOBAL_WORK_SIZE)
    MM_CASE(CL_PLATFORM_NOT_FOUND_KHR)
#undef MM_CASE
    default: return "CL_UNKNOWN_ERROR";
  }
}

void rethrow_as_device_error(const std::string& what) {
  try {
    throw;
  } catch (const cl::BuildError& e) {
    std::ostringstream text;
    text << what << ": kernel build failed (" << e.what() << ": " << error_name(e.err()) << "); build log:";
    for (const auto& [device, log] : e.getBuildLog()) text << shortened_log(log);
    throw DeviceError(text.str());
  } catch (const cl::Error& e) {
    throw DeviceError(what + ": " + e.what() + ": " + error_name(e.err()));
  }
}

Runtime::Runtime(cl::Device device, bool is_gpu, const OpenClOptions& options)
    : device_(std::move(device)), is_gpu_(is_gpu), fault_(options.fault) {
  try {
    context_ = cl::Context(device_);
    queue_ = cl::CommandQueue(context_, device_);
    cl::Platform platform(device_.getInfo<CL_DEVICE_PLATFORM>());
    description_ = platform.getInfo<CL_PLATFORM_NAME>() + " / " + device_.getInfo<CL_DEVICE_NAME>() + " (driver " +
                   device_.getInfo<CL_DRIVER_VERSION>() + ", " + device_.getInfo<CL_DEVICE_VERSION>() + ")";
    max_alloc_bytes_ = device_.getInfo<CL_DEVICE_MAX_MEM_ALLOC_SIZE>();
    std::string build_options = "-cl-std=CL1.2";
    // Correctly rounded division and sqrt make the filter's means and ranges equal the CPU's bits.
    if (device_.getInfo<CL_DEVICE_SINGLE_FP_CONFIG>() & CL_FP_CORRECTLY_ROUNDED_DIVIDE_SQRT) {
      build_options += " -cl-fp32-correctly-rounded-divide-sqrt";
    }
    // Without fp64 (or with it turned off) the sums take the float path of pair_sums.
    has_fp64_ = options.fp64 && device_.getInfo<CL_DEVICE_EXTENSIONS>().find("cl_khr_fp64") != std::string::npos;
    if (has_fp64_) build_options += " -DMM_HAVE_FP64=1";
    has_voxel_means_ =
        has_fp64_ && device_.getInfo<CL_DEVICE_EXTENSIONS>().find("cl_khr_int64_base_atomics") != std::string::npos;
    if (has_voxel_means_) build_options += " -DMM_HAVE_VOXEL_MEANS=1";
    const bool broken = fault_.kind == InjectedFault::Kind::kBuild;
    program_ = cl::Program(context_, kernel_source() + (broken ? kInjectedBuildFault : ""));
    program_.build({device_}, build_options.c_str());
  } catch (...) {
    rethrow_as_device_error("OpenCL setup on " + (description_.empty() ? std::string("device") : description_));
  }
}

std::shared_ptr<Runtime> Runtime::create(const OpenClOptions& options) {
  const Candidate c = pick_device(options);
  return std::make_shared<Runtime>(c.device, c.is_gpu, options);
}

cl::Buffer Runtime::buffer(cl_mem_flags flags, std::size_t bytes, void* host) {
  if (fault_.kind == InjectedFault::Kind::kAlloc && ++allocations_ == fault_.at) {
    throw cl::Error(CL_MEM_OBJECT_ALLOCATION_FAILURE, "clCreateBuffer (injected by MINEMAP_OPENCL_INJECT_FAULT)");
  }
  return cl::Buffer(context_, flags, bytes, host);
}

void Runtime::launch(const cl::Kernel& kernel, std::size_t global, std::size_t local) {
  if (fault_.kind == InjectedFault::Kind::kLaunch && ++launches_ == fault_.at) {
    throw cl::Error(CL_OUT_OF_RESOURCES, "clEnqueueNDRangeKernel (injected by MINEMAP_OPENCL_INJECT_FAULT)");
  }
  queue_.enqueueNDRangeKernel(kernel, cl::NullRange, cl::NDRange(global), cl::NDRange(local));
}

std::size_t Runtime::work_group_size(const cl::Kernel& kernel, std::size_t wanted) const {
  const std::size_t limit = std::min(kernel.getWorkGroupInfo<CL_KERNEL_WORK_GROUP_SIZE>(device_),
                                     device_.getInfo<CL_DEVICE_MAX_WORK_GROUP_SIZE>());
  std::size_t size = 1;
  while (size * 2 <= std::min(limit, wanted)) size *= 2;
  return size;
}

}  // namespace minemap::opencl
