// OpenCL faults, each made real or injected through the path a real one takes (runtime.hpp):
// no platform, a kernel build failure, an out-of-resources launch, device memory exhausted (in the
// slice filter and in a cloud upload). Each runs the `minemap` program in a child process with the
// fault in its environment only, on a 3-scan simulated survey, and checks: exit code, exactly one
// output line that reports the fault, and poses equal, bit for bit, to a `--backend cpu` run's.
//
// What "falls back" means: a setup fault (no platform, build failure) makes `--backend auto` map on
// the CPU and say why in its one "backend:" line, and makes `--backend opencl` exit 6; a fault once
// mapping has begun makes either backend match the whole survey again on the CPU, with one "note:".
// On a machine whose only OpenCL device is PoCL, `auto` never maps on it, so the mid-run faults use
// `--backend opencl`: with no OpenCL platform these tests fail (exit 6), they never skip.
#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#if MINEMAP_WITH_OPENCL
#include "minemap/opencl/runtime.hpp"
#endif
#include "test_support.hpp"

namespace minemap {
namespace {

using test::lines_containing;
using test::run_cli;
using test::run_cli_with_env;
using test::TempDir;

/// A 3-scan simulated survey and its `--backend cpu` map, made once per test process. The maps use
/// `--preset simultaneous`: it runs every kernel (the slice filter too, which the default's voxel
/// reduction does not), and the injected faults below count its allocations and launches.
class Faults : public ::testing::Test {
 protected:
  static constexpr const char* kPreset = " --preset simultaneous";
  static void SetUpTestSuite() {
    dir_ = new TempDir("minemap-faults");
    std::string output;
    ASSERT_EQ(run_cli("simulate --out " + survey() + " --scans 3", &output), 0) << output;
    ASSERT_EQ(run_cli("map " + survey() + " --out " + out("cpu") + " --backend cpu" + kPreset, &output), 0) << output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }

  static std::string survey() { return (*dir_ / "survey").string(); }
  static std::string out(const std::string& name) { return (*dir_ / ("out-" + name)).string(); }

  /// `minemap map` on the survey into out(name), with `environment` set in the child only.
  static int map(const std::string& environment, const std::string& backend, const std::string& name,
                 std::string* output) {
    return run_cli_with_env(environment, "map " + survey() + " --out " + out(name) + " --backend " + backend + kPreset,
                            output);
  }

  /// Every pose-bearing output (scanNNN.pose, scanNNN.frames, trajectory.tum) equals the CPU run's bytes,
  /// and report.json says the CPU backend made it.
  static void expect_cpu_poses(const std::string& name) {
    for (const char* file : {"scan000.pose", "scan001.pose", "scan002.pose", "scan000.frames", "scan001.frames",
                             "scan002.frames", "trajectory.tum"}) {
      ASSERT_TRUE(std::filesystem::exists(std::filesystem::path(out(name)) / file)) << file;
      EXPECT_EQ(test::read_text(std::filesystem::path(out(name)) / file),
                test::read_text(std::filesystem::path(out("cpu")) / file))
          << file;
    }
    const auto report = nlohmann::json::parse(test::read_text(std::filesystem::path(out(name)) / "report.json"));
    const auto cpu = nlohmann::json::parse(test::read_text(std::filesystem::path(out("cpu")) / "report.json"));
    EXPECT_EQ(report["backend"].get<std::string>().rfind("cpu", 0), 0u) << report["backend"];
    for (std::size_t i = 0; i < cpu["scans"].size(); ++i) {
      EXPECT_EQ(report["scans"][i]["pose"], cpu["scans"][i]["pose"]) << i;
    }
  }

  /// Exactly one line names the fault (not one per scan); returns it.
  static std::string the_one_line_naming(const std::string& output, const std::string& fault) {
    const auto lines = lines_containing(output, fault);
    EXPECT_EQ(lines.size(), 1u) << output;
    return lines.empty() ? std::string() : lines.front();
  }

  static TempDir* dir_;
};

TempDir* Faults::dir_ = nullptr;

TEST_F(Faults, NoPlatformMapsOnTheCpuWithOneWarningOrExitsSixForOpenCl) {
  // Real: the ICD loader finds no vendor file, so clGetPlatformIDs reports CL_PLATFORM_NOT_FOUND_KHR.
  TempDir vendors("minemap-no-icd");
  const std::string no_platform = "OCL_ICD_VENDORS=" + vendors.path().string();
  std::string output;
  ASSERT_EQ(map(no_platform, "auto", "no-platform", &output), 0) << output;
  const std::string line = the_one_line_naming(output, "no OpenCL platform found");
  EXPECT_EQ(line.rfind("backend: CPU backend (TBB): ", 0), 0u) << line;
  EXPECT_TRUE(lines_containing(output, "note:").empty()) << output;
  expect_cpu_poses("no-platform");

  EXPECT_EQ(map(no_platform, "opencl", "no-platform-opencl", &output), 6) << output;
  const std::string error = the_one_line_naming(output, "no OpenCL platform found");
  EXPECT_EQ(error.rfind("minemap: OpenCL backend unavailable: ", 0), 0u) << error;
  EXPECT_FALSE(std::filesystem::exists(out("no-platform-opencl"))) << "nothing is written";
}

TEST_F(Faults, KernelBuildFailureMapsOnTheCpuWithOneWarningAndTheBuildLog) {
  // The compiler really gets a broken source (an invalid kernel appended) and clBuildProgram fails.
  // `auto` builds kernels only for a device it would use: a GPU, or the device the user names, so
  // on a machine whose only device is PoCL the test names it.
  std::string output;
  ASSERT_EQ(map("MINEMAP_OPENCL_INJECT_FAULT=build MINEMAP_OPENCL_DEVICE=portable", "auto", "build", &output), 0)
      << output;
  const std::string line = the_one_line_naming(output, "CL_BUILD_PROGRAM_FAILURE");
  EXPECT_EQ(line.rfind("backend: CPU backend (TBB): OpenCL setup on ", 0), 0u) << line;
  EXPECT_NE(line.find("kernel build failed"), std::string::npos) << line;
  // The compiler's own log follows, naming the broken declaration.
  EXPECT_FALSE(lines_containing(output, "not_opencl_c").empty()) << output;
  EXPECT_TRUE(lines_containing(output, "note:").empty()) << output;
  expect_cpu_poses("build");

  EXPECT_EQ(map("MINEMAP_OPENCL_INJECT_FAULT=build", "opencl", "build-opencl", &output), 6) << output;
  const std::string error = the_one_line_naming(output, "CL_BUILD_PROGRAM_FAILURE");
  EXPECT_EQ(error.rfind("minemap: OpenCL backend unavailable: ", 0), 0u) << error;
}

TEST_F(Faults, OutOfResourcesLaunchMidRunMatchesTheSurveyAgainOnTheCpu) {
  // Launches 1-6 are the slice filter (two per scan); launch 20 is a pairing launch during matching.
  for (const char* fault : {"launch:20", "20"}) {  // the plain number is the launch fault too
    std::string output;
    ASSERT_EQ(map(std::string("MINEMAP_OPENCL_INJECT_FAULT=") + fault, "opencl", "launch", &output), 0) << output;
    const std::string line = the_one_line_naming(output, "CL_OUT_OF_RESOURCES");
    EXPECT_EQ(line.rfind("note: OpenCL failed (OpenCL pairing: clEnqueueNDRangeKernel", 0), 0u) << line;
    EXPECT_NE(line.find("the survey was matched again on the CPU"), std::string::npos) << line;
    EXPECT_EQ(lines_containing(output, "note:").size(), 1u) << output;
    expect_cpu_poses("launch");
  }
}

TEST_F(Faults, DeviceMemoryExhaustedUploadingACloudMatchesTheSurveyAgainOnTheCpu) {
  // Allocation 1 is the backend's partial-sum buffer, 2-37 the two slice-filter passes of each of
  // the three scans (all scans are reduced before any tree is built), 38-41 scan000's data cloud:
  // its upload fails.
  std::string output;
  ASSERT_EQ(map("MINEMAP_OPENCL_INJECT_FAULT=alloc:39", "opencl", "alloc", &output), 0) << output;
  const std::string line = the_one_line_naming(output, "CL_MEM_OBJECT_ALLOCATION_FAILURE");
  EXPECT_EQ(line.rfind("note: OpenCL failed (uploading a cloud to the OpenCL device: clCreateBuffer", 0), 0u) << line;
  EXPECT_EQ(lines_containing(output, "note:").size(), 1u) << output;
  expect_cpu_poses("alloc");
}

TEST_F(Faults, DeviceMemoryExhaustedInTheSliceFilterMatchesTheSurveyAgainOnTheCpu) {
  // Allocation 2 is the slice filter's input buffer for scan000: the filter falls back with the rest.
  std::string output;
  ASSERT_EQ(map("MINEMAP_OPENCL_INJECT_FAULT=alloc:2", "opencl", "alloc-filter", &output), 0) << output;
  const std::string line = the_one_line_naming(output, "CL_MEM_OBJECT_ALLOCATION_FAILURE");
  EXPECT_EQ(line.rfind("note: OpenCL failed (OpenCL slice filter: clCreateBuffer", 0), 0u) << line;
  EXPECT_EQ(lines_containing(output, "note:").size(), 1u) << output;
  expect_cpu_poses("alloc-filter");
}

TEST_F(Faults, AnUnknownInjectionIsRefusedLoudly) {
  std::string output;
  EXPECT_EQ(map("MINEMAP_OPENCL_INJECT_FAULT=sometimes", "opencl", "unknown", &output), 6) << output;
  EXPECT_EQ(lines_containing(output, "MINEMAP_OPENCL_INJECT_FAULT='sometimes' is not understood").size(), 1u) << output;
}

// A backend is an object: setup faults no longer need a fresh process, and one broken backend does
// not stop the next one from working.
TEST(FaultsInProcess, SetupFaultsAreTestedInOneProcessAndLeaveNothingBehind) {
  BackendOptions options;
  options.kind = Backend::kOpenCl;
  options.opencl.fault = opencl::InjectedFault::parse("build");
  try {
    (void)make_backend(options);
    ADD_FAILURE() << "a broken kernel build made a backend";
  } catch (const BackendError& e) {
    EXPECT_NE(std::string(e.what()).find("CL_BUILD_PROGRAM_FAILURE"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not_opencl_c"), std::string::npos) << e.what();
  }
  options.kind = Backend::kAuto;
  options.opencl.device = "portable";  // auto builds only for a device it would use: name PoCL
  const BackendChoice fallback = make_backend(options);
  EXPECT_EQ(fallback.backend->name(), "cpu");
  EXPECT_NE(fallback.message.find("kernel build failed"), std::string::npos) << fallback.message;
  options.kind = Backend::kOpenCl;
  options.opencl.fault = {};
  EXPECT_EQ(make_backend(options).backend->name(), "opencl");  // throws (the test fails) without OpenCL
}

TEST(FaultsInProcess, ARealAllocationFailureBecomesADeviceError) {
#if !MINEMAP_WITH_OPENCL
  FAIL() << "minemap was built without OpenCL";
#else
  // Not injected: a buffer beyond CL_DEVICE_MAX_MEM_ALLOC_SIZE makes the real clCreateBuffer fail.
  opencl::OpenClOptions options;
  options.allow_cpu_device = true;
  std::shared_ptr<opencl::Runtime> runtime;
  ASSERT_NO_THROW(runtime = opencl::Runtime::create(options));
  try {
    try {
      (void)runtime->buffer(CL_MEM_READ_WRITE, runtime->max_alloc_bytes() + 4096);
    } catch (...) {
      opencl::rethrow_as_device_error("test allocation");
    }
    ADD_FAILURE() << "a buffer beyond the allocation limit was created";
  } catch (const BackendError& e) {
    EXPECT_NE(std::string(e.what()).find("test allocation: clCreateBuffer: CL_"), std::string::npos) << e.what();
  }
#endif
}

}  // namespace
}  // namespace minemap
