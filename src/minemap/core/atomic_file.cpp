#include "minemap/core/atomic_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "minemap/core/error.hpp"

namespace minemap {
namespace {

std::filesystem::path temp_path_for(const std::filesystem::path& path) {
  return path.string() + std::string(kTempSuffix) + std::to_string(::getpid());
}

/// Flushes a file (or folder) to disk; false when the flush failed (e.g. disk full on write-back).
bool fsync_path(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY);
  if (fd < 0) return false;
  const bool ok = ::fsync(fd) == 0;
  ::close(fd);
  return ok;
}

void commit_temp(const std::filesystem::path& tmp, const std::filesystem::path& path) {
  std::error_code ec;
  if (!fsync_path(tmp)) {
    std::filesystem::remove(tmp, ec);
    throw OutputError("cannot write " + path.string() + ": flushing to disk failed");
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw OutputError("cannot write " + path.string() + ": rename failed: " + ec.message());
  }
  // The rename itself is durable only once the folder's entry is on disk.
  fsync_path(path.parent_path().empty() ? std::filesystem::path(".") : path.parent_path());
}

}  // namespace

void write_file_atomically(const std::filesystem::path& path, std::string_view content) {
  write_bytes_atomically(path, {reinterpret_cast<const std::uint8_t*>(content.data()), content.size()});
}

void write_file_atomically(const std::filesystem::path& path, const std::function<void(std::ostream&)>& writer) {
  const auto tmp = temp_path_for(path);
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw OutputError("cannot write " + path.string() + ": " + std::strerror(errno));
    try {
      writer(out);
      out.flush();
      if (!out) throw OutputError("cannot write " + path.string() + ": write failed (disk full?)");
    } catch (...) {
      out.close();
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      throw;
    }
  }
  commit_temp(tmp, path);
}

void write_bytes_atomically(const std::filesystem::path& path, std::span<const std::uint8_t> bytes) {
  write_file_atomically(path, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  });
}

AtomicOutputFile::AtomicOutputFile(std::filesystem::path path) : path_(std::move(path)), tmp_(temp_path_for(path_)) {
  out_ = std::make_unique<std::ofstream>(tmp_, std::ios::binary | std::ios::trunc);
  if (!*out_) throw OutputError("cannot write " + path_.string() + ": " + std::strerror(errno));
}

AtomicOutputFile::~AtomicOutputFile() {
  if (committed_) return;
  out_.reset();
  std::error_code ec;
  std::filesystem::remove(tmp_, ec);
}

std::ostream& AtomicOutputFile::stream() { return *out_; }

void AtomicOutputFile::commit() {
  out_->flush();
  const bool written = static_cast<bool>(*out_);
  out_->close();
  if (!written) throw OutputError("cannot write " + path_.string() + ": write failed (disk full?)");
  commit_temp(tmp_, path_);  // removes the temp file itself when it fails
  committed_ = true;
}

void remove_stale_temp_files(const std::filesystem::path& dir, bool all_pids) {
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) return;
  const std::string own = std::string(kTempSuffix) + std::to_string(::getpid());
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    const bool match = all_pids ? name.find(kTempSuffix) != std::string::npos
                                : name.size() >= own.size() && name.compare(name.size() - own.size(), own.size(), own) == 0;
    if (match) std::filesystem::remove(entry.path(), ec);
  }
}

}  // namespace minemap
