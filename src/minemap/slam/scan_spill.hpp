#pragma once
// Internal (not installed). Where a long survey keeps the clouds of scans it has let go of
// (docs/scaling.md, "bounded memory"): one file, written once per scan and read back when a scan is
// needed again (a loop's match, a metascan near a return, the map's points at the end). What is
// written is what preparation made (the data, the denser model and the health probe, the map's
// intensities); what is rebuilt on reading is a function of those points alone (each cloud's
// kd-tree, on first use; the model's planes), so a scan read back matches, is judged and is drawn
// exactly as before it was let go.
//
// The file is opened in the folder it is given and unlinked at once (POSIX): nothing is left behind,
// even by a crash, and the disk space returns when the last holder lets go of the spill.
//
// Thread-safety: store() from one thread; load(), points_of() and model_points_of() from any
// (pread, no shared position), also while store() runs. Reading builds clouds on the backend: the CPU backend's
// prepare is reentrant; no other backend is handed one (PartwiseMapper maps on the CPU only).
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <optional>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/slam/mapping_result.hpp"
#include "minemap/slam/mapping_settings.hpp"
#include "minemap/slam/scan_preparation.hpp"

namespace minemap::detail {

class ScanSpill final : public SpilledPoints {
 public:
  /// Opens the (unlinked) file in `folder`, which must exist. Throws OutputError when it cannot be
  /// made there.
  /// `settings` and `backend` must outlive the spill's loads (a result holding it reads only points).
  ScanSpill(const std::filesystem::path& folder, const MappingSettings& settings, ComputeBackend& backend);
  ~ScanSpill() override;
  ScanSpill(const ScanSpill&) = delete;
  ScanSpill& operator=(const ScanSpill&) = delete;

  /// Writes scan i's clouds; a later store of the same scan (prepared again) replaces them. Throws
  /// OutputError when the disk refuses.
  void store(std::size_t i, const PreparedScan& prepared);
  /// Scan i's clouds as stored, rebuilt (`small` supplies what was never let go: counts, times).
  PreparedScan load(std::size_t i, const PreparedScan& small) const;
  /// Scan i's map points (SpilledPoints): its data points and intensities, in the points frame.
  MapPoints points_of(std::size_t i) const override;
  /// Scan i's model points as stored (its data points where it had no model of its own), read
  /// without rebuilding anything: what a metascan's union takes from a scan it does not hold.
  std::vector<Eigen::Vector3f> model_points_of(std::size_t i) const;
  /// Bytes written so far (every version of every scan).
  std::uint64_t bytes() const { return end_; }

 private:
  struct Entry {
    std::uint64_t offset = 0;
    std::uint64_t data = 0, model = 0, probe = 0, intensity = 0;  ///< counts; 0 model/probe: the data cloud
    bool own_model = false, own_probe = false;
  };
  void read_bytes(void* bytes, std::size_t size, std::uint64_t offset) const;
  std::vector<Eigen::Vector3f> read_points(std::uint64_t offset, std::uint64_t count) const;
  std::optional<Entry> find(std::size_t i) const;
  std::shared_ptr<const std::vector<float>> read_intensity(const Entry& e) const;

  const MappingSettings& settings_;
  ComputeBackend& backend_;
  int fd_ = -1;
  std::filesystem::path path_;  ///< for messages (the file itself is gone from the folder)
  std::uint64_t end_ = 0;
  mutable std::mutex entries_mutex_;  ///< entries_ grows while loads read it
  std::vector<std::optional<Entry>> entries_;
};

}  // namespace minemap::detail
