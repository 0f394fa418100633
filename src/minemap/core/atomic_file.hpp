#pragma once
// Output files are never half-written: content goes to a temp file beside the target, is flushed
// and fsync'd, then renamed over the target in one step. An interrupted run leaves either the old
// file or the new one, and at most a temp file that `remove_stale_temp_files` cleans up.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <ostream>
#include <span>
#include <string>
#include <string_view>

namespace minemap {

/// Writes `content` to `path` atomically. Throws OutputError naming the path on failure.
void write_file_atomically(const std::filesystem::path& path, std::string_view content);

/// Streams into a temp file through `writer`, then renames it to `path`. If `writer` throws, the
/// temp file is removed and `path` keeps its old content.
void write_file_atomically(const std::filesystem::path& path, const std::function<void(std::ostream&)>& writer);

/// A file written in pieces (a cloud too large to hold): its bytes go to a temp file beside `path`,
/// which becomes `path` only when commit() succeeds. Destroyed uncommitted (an exception, a stop),
/// it removes the temp file and leaves `path` as it was. Thread-safety: one thread.
class AtomicOutputFile {
 public:
  explicit AtomicOutputFile(std::filesystem::path path);
  ~AtomicOutputFile();
  AtomicOutputFile(const AtomicOutputFile&) = delete;
  AtomicOutputFile& operator=(const AtomicOutputFile&) = delete;
  /// The temp file's stream (binary; seekp allowed, to patch a header).
  std::ostream& stream();
  /// Flushes, fsyncs and renames over `path`. Throws OutputError naming `path` on failure.
  void commit();
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
  std::filesystem::path tmp_;
  std::unique_ptr<std::ofstream> out_;
  bool committed_ = false;
};

/// Binary variant.
void write_bytes_atomically(const std::filesystem::path& path, std::span<const std::uint8_t> bytes);

/// Suffix of temp files ("<name>.minemap-tmp-<pid>"), so cleanup can find them.
inline constexpr std::string_view kTempSuffix = ".minemap-tmp-";

/// Removes temp files left in `dir` by this process (pid match) or by any process when `all_pids`.
void remove_stale_temp_files(const std::filesystem::path& dir, bool all_pids = false);

}  // namespace minemap
