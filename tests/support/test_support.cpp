#include "test_support.hpp"

#include <unistd.h>

#include <array>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <sys/wait.h>

namespace minemap::test {

std::unique_ptr<ComputeBackend> opencl_backend(const opencl::OpenClOptions* options) {
  BackendOptions backend = backend_options_from_environment(Backend::kOpenCl);
  if (options) backend.opencl = *options;
  return make_backend(backend).backend;
}

std::vector<Pose> poses_of(const MappingResult& result) {
  std::vector<Pose> poses;
  for (const auto& s : result.scans) poses.push_back(s.pose_cm);
  return poses;
}

std::vector<Pose> odometry_of(const std::vector<Scan>& scans) {
  std::vector<Pose> poses;
  for (const auto& s : scans) poses.push_back(s.pose_cm);
  return poses;
}

std::unique_ptr<ComputeBackend> backend_named(const std::string& name) {
  if (name == "cpu") return make_cpu_backend();
  if (name == "opencl") return opencl_backend();
  throw std::invalid_argument("no backend named " + name);
}

std::filesystem::path shared_data_dir() { return MINEMAP_SHARED_DATA_DIR; }

TempDir::TempDir(const std::string& tag) {
  static int counter = 0;
  path_ = std::filesystem::temp_directory_path() /
          (tag + "-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
  std::filesystem::remove_all(path_);
  std::filesystem::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

void write_text(const std::filesystem::path& path, const std::string& content) {
  std::ofstream out(path, std::ios::binary);
  out << content;
  if (!out) throw std::runtime_error("cannot write test input " + path.string());
}

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::vector<Eigen::Vector3f> random_cloud(std::size_t count, float lo, float hi, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> dist(lo, hi);
  std::vector<Eigen::Vector3f> cloud(count);
  for (auto& p : cloud) p = Eigen::Vector3f(dist(rng), dist(rng), dist(rng));
  return cloud;
}

namespace {

int run_command(const std::string& command, std::string* output) {
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) throw std::runtime_error("popen failed");
  std::string text;
  std::array<char, 4096> buffer{};
  while (std::fgets(buffer.data(), buffer.size(), pipe)) text += buffer.data();
  const int status = ::pclose(pipe);
  if (output) *output = text;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

int run_cli(const std::string& args, std::string* output) {
  return run_command(std::string(MINEMAP_CLI_PATH) + " " + args + " 2>&1", output);
}

int run_cli_with_env(const std::string& environment, const std::string& args, std::string* output) {
  return run_command("env " + environment + " " + std::string(MINEMAP_CLI_PATH) + " " + args + " 2>&1", output);
}

std::vector<std::string> lines_containing(const std::string& text, const std::string& needle) {
  std::vector<std::string> found;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.find(needle) != std::string::npos) found.push_back(line);
  }
  return found;
}

}  // namespace minemap::test
