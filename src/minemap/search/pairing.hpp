#pragma once
// Closest-point pairing for ICP (section IV.D of the paper) and the sums Horn's method needs.
//
// One interface, two backends behind one dispatch point (`make_pairing_backend`):
//  - CpuPairingBackend (pairing_cpu.cpp): TBB-parallel over queries, deterministic;
//  - the OpenCL backend (host/minemap/opencl/pairing_opencl.cpp): one work-item per query, trees
//    uploaded once per cloud, only the per-group partial sums cross the bus each iteration.
//
// Frames: a data cloud is paired against one or more model clouds. Each model is placed by
// `model_from_data` (T_model_data, double). Pairs and sums are expressed in the DATA cloud's frame,
// so the union of several models (simultaneous matching) needs no common world frame, and all sums
// are centred on the data cloud's centroid (no precision loss for clouds far from any origin).
#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/search/kdtree.hpp"

namespace minemap {

/// A backend failed while running (an OpenCL device ran out of resources or was lost). Callers
/// that can redo their work on the CPU catch this and fall back.
class BackendError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// How a closest point is found (Table I of the paper).
enum class SearchMethod {
  kExact,        ///< bucket kd-tree with backtracking (ball-within-bounds)
  kApproximate,  ///< descend to the query's bucket, return the bucket mean; no backtracking
  kBruteForce,   ///< every model point: the O(n*m) baseline
};
const char* to_string(SearchMethod method);
SearchMethod parse_search_method(const std::string& text);  ///< "kd", "apx", "brute"

struct PairingSettings {
  float max_pair_dist_cm = 25.0f;  ///< pairs farther apart are dropped (3DTK's default, 25 cm)
};

/// Sums over the pairs (p in the data cloud, m its closest model point, both in the data frame),
/// centred on `reference_cm`: p' = p - r, m' = m - r. Held in double; deterministic for a backend.
struct PairSums {
  double count = 0.0;
  Eigen::Vector3d sum_data = Eigen::Vector3d::Zero();         ///< sum of p'
  Eigen::Vector3d sum_model = Eigen::Vector3d::Zero();        ///< sum of m'
  Eigen::Matrix3d sum_data_model = Eigen::Matrix3d::Zero();   ///< sum of p' m'^T
  double sum_squared_distance_cm2 = 0.0;                      ///< sum of |p - m|^2
  Eigen::Vector3d reference_cm = Eigen::Vector3d::Zero();

  double rms_cm() const;
  PairSums& operator+=(const PairSums& other);  ///< both must share reference_cm
  /// Adds one pair, centred: p' = p - reference_cm, m' = m - reference_cm. Written out term by
  /// term: kernels/correspondence.cl (pair_sums_blocks) repeats these operations in this order.
  void add_pair(const Eigen::Vector3f& p, const Eigen::Vector3f& m, float squared_distance_cm2);
  /// The 17 terms in kernel order: count, sum p', sum m', sum p' m'^T (row-major), sum |p - m|^2.
  static PairSums from_terms(const double* terms, const Eigen::Vector3d& reference_cm);
};

/// Pairs are summed per block of this many consecutive data points, in double and in index order,
/// and the blocks are added in order: the CPU backend does so (TBB over blocks, so any thread count
/// gives the same bits), and the OpenCL backend does the same per work-item on devices with double
/// precision, so the two backends' sums, and hence their poses, are bit-identical.
inline constexpr int kPairSumBlock = 64;

/// The closest model point of one query, for tests and overlap counting.
struct NearestPair {
  float squared_distance_cm2 = -1.0f;  ///< < 0: no model point within max_pair_dist_cm
  std::int32_t model = -1;             ///< index into the models passed to the search
  std::int32_t model_point = -1;       ///< original index in that model cloud (-1 for bucket means)
  Eigen::Vector3f position_cm = Eigen::Vector3f::Zero();  ///< the model point, in the DATA frame
};

/// A cloud prepared for pairing: its points (original order) and its kd-tree. Backends attach
/// device copies to it. Thread-safety: immutable after preparation.
class PreparedCloud {
 public:
  virtual ~PreparedCloud() = default;
  std::span<const Eigen::Vector3f> points() const { return points_; }
  const KdTree& tree() const { return tree_; }
  const Eigen::Vector3d& centroid_cm() const { return centroid_cm_; }

 protected:
  PreparedCloud(std::vector<Eigen::Vector3f> points, const KdTreeSettings& tree_settings);

 private:
  std::vector<Eigen::Vector3f> points_;
  KdTree tree_;
  Eigen::Vector3d centroid_cm_ = Eigen::Vector3d::Zero();
};

/// A model cloud and where it sits relative to the data cloud.
struct ModelPlacement {
  const PreparedCloud* model = nullptr;
  Pose model_from_data = Pose::Identity();  ///< T_model_data
};

/// The correspondence search. Thread-safety: a backend may be used from one thread at a time
/// (it parallelises internally); prepared clouds may be shared between threads.
class PairingBackend {
 public:
  virtual ~PairingBackend() = default;
  /// "cpu" or "opencl", plus device details for reports.
  virtual std::string name() const = 0;
  virtual std::string device_description() const = 0;

  /// Builds the kd-tree (and device copies) for a cloud used as data and/or model.
  virtual std::shared_ptr<const PreparedCloud> prepare(std::vector<Eigen::Vector3f> points_cm,
                                                       const KdTreeSettings& tree_settings) = 0;

  /// Pairs every data point with its closest point over all `models` and returns the sums,
  /// centred on the data cloud's centroid.
  virtual PairSums pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                SearchMethod method, const PairingSettings& settings) = 0;

  /// The closest pair of every data point (tests, diagnostics).
  virtual std::vector<NearestPair> nearest(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                           SearchMethod method, const PairingSettings& settings) = 0;
};

enum class Backend { kAuto, kCpu, kOpenCl };
const char* to_string(Backend backend);
Backend parse_backend(const std::string& text);  ///< "auto", "cpu", "opencl"

/// What `make_pairing_backend` chose and why (for reports and the CLI's first line).
struct BackendChoice {
  std::unique_ptr<PairingBackend> backend;
  std::string message;  ///< e.g. why OpenCL was not used
};

/// The dispatch point. kCpu: TBB. kOpenCl: OpenCL or throws BackendError saying why not.
/// kAuto: OpenCL on a GPU device if one works, else the CPU path (PoCL on a 2-core CPU is slower
/// than TBB), with the reason in `message`.
BackendChoice make_pairing_backend(Backend requested);

/// The CPU backend directly (tests, oracles).
std::unique_ptr<PairingBackend> make_cpu_pairing_backend();

}  // namespace minemap
