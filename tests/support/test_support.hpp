#pragma once
// Helpers shared by the unit tests: paths to shared data, temp folders, seeded random clouds.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "minemap/backend/make_backend.hpp"
#include "minemap/slam/survey_matching.hpp"

namespace minemap::test {

/// The OpenCL backend as the tests use it: PoCL allowed, MINEMAP_OPENCL_* from the environment
/// applied (the float-sum run sets MINEMAP_OPENCL_FP64=off). Throws without OpenCL, so a test that
/// asks for it fails, never skips.
std::unique_ptr<ComputeBackend> opencl_backend(const opencl::OpenClOptions* options = nullptr);

/// The registered poses of a mapping run (pose_cm, scan by scan), and the initial ones of its scans:
/// what pose_errors compares with ground truth.
std::vector<Pose> poses_of(const MappingResult& result);
std::vector<Pose> odometry_of(const std::vector<Scan>& scans);

/// "cpu" or "opencl" (opencl_backend()).
std::unique_ptr<ComputeBackend> backend_named(const std::string& name);

/// ../shared/data beside the checkout (MINEMAP_SHARED_DATA_DIR at configure time).
std::filesystem::path shared_data_dir();

/// A fresh, empty folder under the system temp dir, removed by the destructor.
class TempDir {
 public:
  explicit TempDir(const std::string& tag = "minemap-test");
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

/// Writes `content` to `path` (test inputs; not atomic).
void write_text(const std::filesystem::path& path, const std::string& content);
std::string read_text(const std::filesystem::path& path);

/// `count` points uniform in the box [lo, hi]^3, fixed seed.
std::vector<Eigen::Vector3f> random_cloud(std::size_t count, float lo, float hi, std::uint32_t seed);

/// Runs the minemap program with `args`; returns its exit code, stdout+stderr in `output`.
int run_cli(const std::string& args, std::string* output = nullptr);

/// As run_cli, with `environment` ("NAME=value NAME2=value2", shell words) set in the child only
/// (through env(1)); the test process's own environment is left as it was.
int run_cli_with_env(const std::string& environment, const std::string& args, std::string* output = nullptr);

/// The lines of `text` that contain `needle`.
std::vector<std::string> lines_containing(const std::string& text, const std::string& needle);

}  // namespace minemap::test
