#pragma once
// Internal (not installed). Where every scan of a run stands: its prepared clouds, where it
// started, and its outcome so far (pose, frames, match, health). The one writer of a scan's pose
// and frames: place() (a match, or the pose graph, put it there), fail() (no registration: it stays
// where its match began) and restore() (a resumed run). Every stage reads poses here and writes
// them only through these. Also the spatial queries over the poses (bounds, nearby scans).
//
// Thread-safety: one thread writes; reads from parallel loops between writes are safe.
#include <cstddef>
#include <span>
#include <vector>

#include "minemap/core/scan.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/slam/mapping_result.hpp"
#include "minemap/slam/scan_preparation.hpp"

namespace minemap::detail {

class SurveyState {
 public:
  /// Appends `scan` at its initial pose (T_world_file = scan.pose_cm); returns its index.
  std::size_t add(const Scan& scan, PreparedScan prepared);
  std::size_t size() const { return scans_.size(); }

  const PreparedScan& prepared(std::size_t i) const { return scans_[i].prepared; }
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
  void count_relaxation_match(std::size_t i) { ++scans_[i].outcome.relaxation_matches; }
  void set_match_time(std::size_t i, double seconds) { scans_[i].outcome.match_s = seconds; }

  /// World bounds of scan i's model at `world_from_points`, from its kd-tree's box (8 corners).
  Bounds3d bounds_at(std::size_t i, const Pose& world_from_points) const;
  /// Scans 0..limit-1 (not i) whose world bounds come within `margin_cm` of scan i's at `at`,
  /// closest scan position first: searching near, dense scans first tightens the pair bound early.
  std::vector<std::size_t> nearby(std::size_t i, const Pose& at, std::size_t limit, double margin_cm) const;
  /// The models of `indices` where they stand.
  std::vector<WorldModel> models_of(std::span<const std::size_t> indices) const;

  std::vector<ScanOutcome> outcomes() const;

 private:
  struct ScanState {
    PreparedScan prepared;
    Pose odometry = Pose::Identity();          ///< initial T_world_points
    Pose points_from_file = Pose::Identity();  ///< T_points_file: pose_cm = world_from_points * this
    ScanOutcome outcome;                       ///< outcome.world_from_points: the current pose
  };
  std::vector<ScanState> scans_;
  std::size_t first_moved_ = static_cast<std::size_t>(-1);  ///< the first scan whose initial pose is its own
};

}  // namespace minemap::detail
