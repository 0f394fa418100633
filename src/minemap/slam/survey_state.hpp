#pragma once
// Internal (not installed). Where every scan of a run stands: its prepared clouds, where it
// started, and its outcome so far (pose, frames, match, health). The one writer of a scan's pose
// and frames: place() (a match, or the pose graph, put it there), fail() (no registration: it stays
// where its match began) and restore() (a resumed run). Every stage reads poses here and writes
// them only through these. Also the spatial queries over the poses (bounds, nearby scans).
//
// A memory bound (bound_memory, docs/scaling.md): the clouds of the scans least recently used are
// written to a spill file and let go whenever those held come to more than the bound
// (release_over_budget); prepared() reads a scan let go of back, the same clouds bit for bit.
//
// Thread-safety: one thread writes; reads from parallel loops between writes are safe (prepared()
// reads back under a lock). release_over_budget is a write: it ends the references prepared() gave
// to the scans it lets go of.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include "minemap/core/scan.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/slam/mapping_result.hpp"
#include "minemap/slam/scan_preparation.hpp"
#include "minemap/slam/scan_spill.hpp"

namespace minemap::detail {

/// A scan's model points, held one of two ways (see SurveyState::model_points).
class ModelPoints {
 public:
  explicit ModelPoints(std::shared_ptr<const PreparedCloud> held) : held_(std::move(held)) {}
  explicit ModelPoints(std::vector<Eigen::Vector3f> read) : read_(std::move(read)) {}
  std::span<const Eigen::Vector3f> points() const { return held_ ? held_->points() : std::span(read_); }
  /// The model cloud itself when held (with its backend's device copy), else null.
  const PreparedCloud* cloud() const { return held_.get(); }

 private:
  std::shared_ptr<const PreparedCloud> held_;
  std::vector<Eigen::Vector3f> read_;
};

class SurveyState {
 public:
  /// Appends `scan` at its initial pose (T_world_file = scan.pose_cm); returns its index.
  std::size_t add(const Scan& scan, PreparedScan prepared);
  std::size_t size() const { return scans_.size(); }

  /// Scan i's clouds (read back from the spill when they were let go of).
  const PreparedScan& prepared(std::size_t i) const;
  /// Scan i's model points (kept alive by the value): shared with its model cloud when held, else
  /// read from the spill without taking the scan back (nothing rebuilt, the bound not touched), so
  /// a union over hundreds of scans let go of costs their points' bytes, not their trees and planes.
  ModelPoints model_points(std::size_t i) const;
  /// Holds at most `held_bytes` of clouds (points, the trees built so far, planes), the rest in
  /// `spill`. Before the first add.
  void bound_memory(std::shared_ptr<ScanSpill> spill, std::size_t held_bytes);
  /// Lets go of the least recently used scans' clouds (never the newest scan's) until those held fit
  /// the bound; nothing without one.
  void release_over_budget();
  /// Where the map points of the scans let go of are (null: no bound).
  std::shared_ptr<const SpilledPoints> spilled() const { return spill_; }
  /// Bytes written to the spill so far (0: no bound, or nothing let go of).
  std::uint64_t spilled_bytes() const { return spill_ ? spill_->bytes() : 0; }
  const ScanOutcome& outcome(std::size_t i) const { return scans_[i].outcome; }
  /// Current T_world_points.
  const Pose& pose(std::size_t i) const { return scans_[i].outcome.world_from_points; }
  /// The initial T_world_points (odometry, or the initial guess).
  const Pose& odometry(std::size_t i) const { return scans_[i].odometry; }
  /// T_points_file of scan i (its local origin): T_world_file = pose(i) * points_from_file(i).
  const Pose& points_from_file(std::size_t i) const { return scans_[i].points_from_file; }
  /// Whether some scan up to i starts from a pose of its own (T_world_file not the first scan's):
  /// the survey carries odometry or initial poses there.
  bool odometry_moved_by(std::size_t i) const { return first_moved_ <= i; }
  /// Scan i prepared again (deskewed by a better motion): its clouds and counts; its pose stays.
  void set_prepared(std::size_t i, PreparedScan prepared);
  bool registered(std::size_t i) const { return scans_[i].outcome.registered; }
  const RegistrationHealth& health(std::size_t i) const { return scans_[i].outcome.health; }

  /// A match put scan i at `world_from_points`: its pose, a frame, the match; registered.
  void place(std::size_t i, const Pose& world_from_points, const IcpResult& match);
  /// The pose graph moved scan i: its pose and a frame; its match stays.
  void place(std::size_t i, const Pose& world_from_points);
  /// No registration of scan i succeeded: it stays at `start`, where its match began (no frame),
  /// unregistered, and `match` says why.
  void fail(std::size_t i, const Pose& start, const IcpResult& match);
  /// A resumed run: scan i as an earlier run left it (its clouds, counts and points stay its own).
  void restore(std::size_t i, const ScanOutcome& saved);
  void judged(std::size_t i, RegistrationHealth health) { scans_[i].outcome.health = std::move(health); }
  /// How many times a scan other than the newest has moved (place, fail, restore): a metascan built
  /// from the scans before the newest stays theirs while this does not change.
  std::uint64_t older_moves() const { return older_moves_; }
  void count_relaxation_match(std::size_t i) { ++scans_[i].outcome.relaxation_matches; }
  /// What scan i's arrival cost: seconds, and the process's resident memory after it (bytes).
  void set_match_cost(std::size_t i, double seconds, std::size_t resident_bytes) {
    scans_[i].outcome.match_s = seconds;
    scans_[i].outcome.resident_mb = static_cast<double>(resident_bytes) / (1024.0 * 1024.0);
  }

  /// World bounds of scan i's model at `world_from_points`, from its kd-tree's box (8 corners).
  Bounds3d bounds_at(std::size_t i, const Pose& world_from_points) const;
  /// Scans 0..limit-1 (not i) whose world bounds come within `margin_cm` of scan i's at `at`,
  /// closest scan position first: searching near, dense scans first tightens the pair bound early.
  std::vector<std::size_t> nearby(std::size_t i, const Pose& at, std::size_t limit, double margin_cm) const;
  /// The models of `indices` where they stand.
  std::vector<WorldModel> models_of(std::span<const std::size_t> indices) const;

  std::vector<ScanOutcome> outcomes() const;

 private:
  /// Counts a move of scan i where it is not the newest (older_moves).
  void count_move(std::size_t i) { older_moves_ += i + 1 < scans_.size() ? 1 : 0; }
  std::uint64_t older_moves_ = 0;
  struct ScanState {
    mutable PreparedScan prepared;  ///< its heavy parts null while let go of (prepared() reads them back)
    Pose odometry = Pose::Identity();          ///< initial T_world_points
    Pose points_from_file = Pose::Identity();  ///< T_points_file: pose_cm = world_from_points * this
    ScanOutcome outcome;                       ///< outcome.world_from_points: the current pose
    Eigen::Vector3f model_min = Eigen::Vector3f::Zero(), model_max = Eigen::Vector3f::Zero();  ///< model's box
    bool model_empty = true;
    // The memory bound's bookkeeping (under spill_mutex_):
    mutable std::uint64_t last_use = 0; ///< when prepared() last gave it out
    mutable bool let_go = false;        ///< its clouds are in the spill, not here
    bool stored = false;                ///< its clouds as they stand are in the spill
  };
  /// Scan i's clouds into the spill (unless there already) and out of memory.
  void let_go(std::size_t i);

  std::vector<ScanState> scans_;
  std::shared_ptr<ScanSpill> spill_;
  std::size_t budget_bytes_ = 0;
  mutable std::mutex spill_mutex_;
  mutable std::uint64_t clock_ = 0;
  std::size_t first_moved_ = static_cast<std::size_t>(-1);  ///< the first scan whose initial pose is its own
};

}  // namespace minemap::detail
