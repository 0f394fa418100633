#include "minemap/slam/scan_spill.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

#include "minemap/core/error.hpp"

namespace minemap::detail {

namespace {

[[noreturn]] void fail(const std::filesystem::path& path, const char* what) {
  throw OutputError("the memory bound's spill file " + path.string() + ": " + what + ": " + std::strerror(errno));
}

}  // namespace

ScanSpill::ScanSpill(const std::filesystem::path& folder, const MappingSettings& settings, ComputeBackend& backend)
    : settings_(settings), backend_(backend) {
  // A name of our own (pid and address), made exclusively, then unlinked: only this process sees it.
  path_ = folder / (".minemap-spill-" + std::to_string(::getpid()) + "-" +
                    std::to_string(reinterpret_cast<std::uintptr_t>(this)));
  fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd_ < 0) fail(path_, "cannot be made");
  ::unlink(path_.c_str());
}

ScanSpill::~ScanSpill() {
  if (fd_ >= 0) ::close(fd_);
}

void ScanSpill::store(std::size_t i, const PreparedScan& prepared) {
  Entry entry;
  entry.offset = end_;
  const auto& data = prepared.cloud->point_vector();
  entry.data = data.size();
  entry.own_model = prepared.model_cloud && prepared.model_cloud != prepared.cloud;
  entry.own_probe = prepared.probe && prepared.probe != prepared.cloud;
  if (entry.own_model) entry.model = prepared.model_cloud->points().size();
  if (entry.own_probe) entry.probe = prepared.probe->points().size();
  if (prepared.used_intensity) entry.intensity = prepared.used_intensity->size();
  const auto write = [&](const void* bytes, std::size_t size) {
    const char* at = static_cast<const char*>(bytes);
    while (size > 0) {
      const ssize_t wrote = ::pwrite(fd_, at, size, static_cast<off_t>(end_));
      if (wrote < 0 && errno == EINTR) continue;
      if (wrote <= 0) fail(path_, "writing");
      at += wrote;
      end_ += static_cast<std::uint64_t>(wrote);
      size -= static_cast<std::size_t>(wrote);
    }
  };
  write(data.data(), data.size() * sizeof(Eigen::Vector3f));
  if (entry.own_model) write(prepared.model_cloud->points().data(), entry.model * sizeof(Eigen::Vector3f));
  if (entry.own_probe) write(prepared.probe->points().data(), entry.probe * sizeof(Eigen::Vector3f));
  if (entry.intensity > 0) write(prepared.used_intensity->data(), entry.intensity * sizeof(float));
  const std::lock_guard lock(entries_mutex_);
  if (entries_.size() <= i) entries_.resize(i + 1);
  entries_[i] = entry;
}

std::optional<ScanSpill::Entry> ScanSpill::find(std::size_t i) const {
  const std::lock_guard lock(entries_mutex_);
  if (i >= entries_.size()) return std::nullopt;
  return entries_[i];
}

void ScanSpill::read_bytes(void* bytes, std::size_t size, std::uint64_t offset) const {
  char* at = static_cast<char*>(bytes);
  while (size > 0) {
    const ssize_t got = ::pread(fd_, at, size, static_cast<off_t>(offset));
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) fail(path_, "reading back");
    at += got;
    offset += static_cast<std::uint64_t>(got);
    size -= static_cast<std::size_t>(got);
  }
}

std::vector<Eigen::Vector3f> ScanSpill::read_points(std::uint64_t offset, std::uint64_t count) const {
  std::vector<Eigen::Vector3f> points(count);
  read_bytes(points.data(), count * sizeof(Eigen::Vector3f), offset);
  return points;
}

PreparedScan ScanSpill::load(std::size_t i, const PreparedScan& small) const {
  const std::optional<Entry> found = find(i);
  if (!found) throw std::logic_error("scan " + std::to_string(i) + " was never spilled");
  const Entry& e = *found;
  PreparedScan scan = small;
  constexpr std::uint64_t kPoint = sizeof(Eigen::Vector3f);
  std::uint64_t at = e.offset;
  // Every tree on first use: the same tree as at first (a function of the points), built only for a
  // search that needs it.
  scan.cloud = backend_.prepare(read_points(at, e.data), settings_.tree, TreeBuild::kOnFirstUse);
  at += e.data * kPoint;
  scan.model_cloud = scan.cloud;
  if (e.own_model) {
    scan.model_cloud = backend_.prepare(read_points(at, e.model), settings_.tree, TreeBuild::kOnFirstUse);
    at += e.model * kPoint;
  }
  scan.probe = scan.cloud;
  if (e.own_probe) {
    scan.probe = backend_.prepare(read_points(at, e.probe), settings_.tree, TreeBuild::kOnFirstUse);
    at += e.probe * kPoint;
  }
  share_with_the_map(scan);
  scan.used_intensity = read_intensity(e);
  scan.planes.reset();
  if (settings_.needs_planes()) scan.planes.emplace(scan.model_cloud->points(), settings_.plane_cell_cm);
  return scan;
}

std::shared_ptr<const std::vector<float>> ScanSpill::read_intensity(const Entry& e) const {
  if (e.intensity == 0) return nullptr;
  std::vector<float> intensity(e.intensity);
  read_bytes(intensity.data(), e.intensity * sizeof(float), e.offset + (e.data + e.model + e.probe) * sizeof(Eigen::Vector3f));
  return std::make_shared<const std::vector<float>>(std::move(intensity));
}

std::vector<Eigen::Vector3f> ScanSpill::model_points_of(std::size_t i) const {
  const std::optional<Entry> e = find(i);
  if (!e) throw std::logic_error("scan " + std::to_string(i) + " was never spilled");
  if (!e->own_model) return read_points(e->offset, e->data);
  return read_points(e->offset + e->data * sizeof(Eigen::Vector3f), e->model);
}

MapPoints ScanSpill::points_of(std::size_t i) const {
  const std::optional<Entry> e = find(i);
  if (!e) return {};
  return {std::make_shared<const std::vector<Eigen::Vector3f>>(read_points(e->offset, e->data)), read_intensity(*e)};
}

}  // namespace minemap::detail
