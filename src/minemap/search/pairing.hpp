#pragma once
// Closest-point pairing for ICP (section IV.D of the paper): what is searched and how. The search
// itself runs in a compute backend (backend/compute_backend.hpp), on the CPU or an OpenCL device.
//
// Frames: a data cloud is paired against one or more model clouds. Each model is placed by
// `model_from_data` (T_model_data, double). Pairs and sums are expressed in the DATA cloud's frame,
// so the union of several models (simultaneous matching) needs no common world frame, and all sums
// are centred on the data cloud's centroid (no precision loss for clouds far from any origin).
#include <Eigen/Core>
#include <atomic>
#include <cstdint>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include "minemap/core/name_table.hpp"
#include "minemap/core/pose.hpp"
#include "minemap/search/kdtree.hpp"

namespace minemap {

/// How a closest point is found (Table I of the paper).
enum class SearchMethod {
  kExact,        ///< bucket kd-tree with backtracking (ball-within-bounds)
  kApproximate,  ///< descend to the query's bucket, return the bucket mean; no backtracking
  kBruteForce,   ///< every model point: the O(n*m) baseline
};
inline constexpr std::array<EnumName<SearchMethod>, 3> kSearchMethodNames{
    {{SearchMethod::kExact, "kd"}, {SearchMethod::kApproximate, "apx"}, {SearchMethod::kBruteForce, "brute"}}};
/// Longer names parse_search_method also takes (the command line offers the short ones).
inline constexpr std::array<EnumName<SearchMethod>, 3> kSearchMethodAliases{
    {{SearchMethod::kExact, "exact"}, {SearchMethod::kApproximate, "approximate"},
     {SearchMethod::kBruteForce, "bruteforce"}}};
const char* to_string(SearchMethod method);
SearchMethod parse_search_method(const std::string& text);  ///< kSearchMethodNames or kSearchMethodAliases

struct PairingSettings {
  /// Pairs farther apart are dropped: 3DTK's default, 25 cm, and the one definition of the pair
  /// bound's default (IcpSettings::max_pair_dist_cm starts from it).
  float max_pair_dist_cm = 25.0f;
  /// The scale of the Geman-McClure kernel that weighs each pair in the sums (shared::
  /// mm_robust_weight: 1/4 at this distance); 0: every pair weighs 1, the paper's sums.
  float robust_scale_cm = 0.0f;
};

/// The closest model point of one query, for tests and overlap counting.
struct NearestPair {
  float squared_distance_cm2 = -1.0f;  ///< < 0: no model point within max_pair_dist_cm
  std::int32_t model = -1;             ///< index into the models passed to the search
  std::int32_t model_point = -1;       ///< original index in that model cloud (-1 for bucket means)
  Eigen::Vector3f position_cm = Eigen::Vector3f::Zero();  ///< the model point, in the DATA frame
};

/// When a cloud's kd-tree is built: at once (a cloud about to be searched), or by the first call
/// of tree() (a moving sensor's sweep: its own trees are searched only if a later step matches
/// against the scan alone, and building them for every sweep cost a tenth of the run).
enum class TreeBuild { kNow, kOnFirstUse };

/// A cloud prepared for pairing by one backend: its points (original order), its kd-tree, and
/// whatever copies the backend keeps (device buffers). Thread-safety: immutable once prepared (a
/// tree built on first use is built once, under std::call_once), so it may be shared between
/// threads; the backend that prepared it must outlive it.
class PreparedCloud {
 public:
  virtual ~PreparedCloud() = default;
  std::span<const Eigen::Vector3f> points() const { return points_; }
  /// The same points as a vector: a scan's points for the map share them (an aliasing shared_ptr
  /// to this cloud) instead of holding a copy.
  const std::vector<Eigen::Vector3f>& point_vector() const { return points_; }
  /// The kd-tree over points(); built here on the first call when prepared with kOnFirstUse.
  const KdTree& tree() const {
    std::call_once(built_, [this] {
      tree_ = KdTree(points_, tree_settings_);
      tree_built_.store(true, std::memory_order_release);
    });
    return tree_;
  }
  /// What the cloud holds in memory, bytes: its points, and its tree once built (a long survey's
  /// memory bound counts it; a device's copies are not counted).
  std::size_t memory_bytes() const {
    return points_.capacity() * sizeof(Eigen::Vector3f) +
           (tree_built_.load(std::memory_order_acquire) ? tree_.memory_bytes() : 0);
  }
  /// The points' bounding box (the tree's, without building it; zero for no points).
  const Eigen::Vector3f& bounds_min() const { return bounds_min_; }
  const Eigen::Vector3f& bounds_max() const { return bounds_max_; }
  bool empty() const { return points_.empty(); }
  /// The centroid, rounded to float: the reference every sum over this cloud is centred on.
  const Eigen::Vector3d& centroid_cm() const { return centroid_cm_; }

 protected:
  PreparedCloud(std::vector<Eigen::Vector3f> points, const KdTreeSettings& tree_settings,
                TreeBuild when = TreeBuild::kNow);

 private:
  std::vector<Eigen::Vector3f> points_;
  KdTreeSettings tree_settings_;
  mutable std::once_flag built_;
  mutable KdTree tree_;
  mutable std::atomic<bool> tree_built_{false};
  Eigen::Vector3f bounds_min_ = Eigen::Vector3f::Zero();
  Eigen::Vector3f bounds_max_ = Eigen::Vector3f::Zero();
  Eigen::Vector3d centroid_cm_ = Eigen::Vector3d::Zero();
};

/// A model cloud and where it sits relative to the data cloud.
struct ModelPlacement {
  const PreparedCloud* model = nullptr;
  Pose model_from_data = Pose::Identity();  ///< T_model_data
  SkippedPoints skip{};
};

/// Throws std::invalid_argument when a model leaves points out (ModelPlacement::skip) and the
/// search is not exact: the backends' one check, before any search.
void require_exact_search_for_skips(std::span<const ModelPlacement> models, SearchMethod method);

}  // namespace minemap
