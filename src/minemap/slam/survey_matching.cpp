#include "minemap/slam/survey_matching.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <functional>
#include <optional>
#include <stdexcept>

#include <tbb/parallel_for.h>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/filter/voxel_filter.hpp"
#include "minemap/registration/match_information.hpp"

namespace minemap {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

/// Everything the matcher holds per scan: its prepared cloud and its current T_world_points.
struct ScanState {
  std::shared_ptr<const PreparedCloud> cloud;        ///< data: matched against others
  std::shared_ptr<const PreparedCloud> model_cloud;  ///< model: others are matched against it (may be `cloud`)
  std::shared_ptr<const PreparedCloud> probe;        ///< every health.probe_stride-th data point: what judging searches
  std::optional<SurfaceNormals> planes;              ///< its model's planes, own frame (health, loop edges)
  Pose odometry = Pose::Identity();  ///< initial T_world_points
  Pose pose = Pose::Identity();      ///< current T_world_points
  Pose points_from_file = Pose::Identity();
};

/// One mapping run on one backend. A backend fault propagates (map_survey starts a fresh matcher
/// on a CPU backend); nothing here is reset by hand.
class SurveyMatcher {
 public:
  SurveyMatcher(const MappingSettings& settings, ComputeBackend& backend, const ProgressCallback& progress,
                const StopRequested& stop_requested)
      : settings_(settings),
        backend_(backend),
        progress_(progress),
        stop_requested_(stop_requested),
        icp_(settings.icp) {
    // A pair of scans that passes the overlap test must also be registrable.
    icp_.termination.min_pairs = std::min(icp_.termination.min_pairs, settings.min_overlap_pairs);
    relaxation_icp_ = icp_;
    if (settings.relaxation_min_step_cm > 0.0) {
      relaxation_icp_.termination.min_translation_step_cm = settings.relaxation_min_step_cm;
    }
    if (settings.relaxation_min_step_deg > 0.0) {
      relaxation_icp_.termination.min_rotation_step_deg = settings.relaxation_min_step_deg;
    }
    result_.backend = backend_.name() + ": " + backend_.device_description();
  }

  /// map_survey: every scan prepared at once (in parallel), then matched in order, then finished.
  MappingResult run(const std::vector<Scan>& scans) {
    total_ = scans.size();
    prepare_all(scans);
    for (std::size_t i = 1; i < count_; ++i) {
      if (stop_requested()) {
        // Scans 0..i-1 are final (a relaxation cut short leaves them where its last match put them).
        result_.interrupted = true;
        result_.scans_matched = i;
        return std::move(result_);
      }
      match_scan(i);
    }
    finish();
    return std::move(result_);
  }

  /// LiveMapper::add: one more scan, prepared alone (the same clouds as prepare_all's), then matched.
  void add(const Scan& scan) {
    total_ = count_ + 1;
    prepare_one(scan);
    if (count_ > 1) match_scan(count_ - 1);
  }

  /// LiveMapper::restore: one more scan prepared, its outcome as a previous run left it.
  void restore(const Scan& scan, const ScanOutcome& outcome) {
    total_ = count_ + 1;
    prepare_one(scan);
    const std::size_t i = count_ - 1;
    ScanOutcome& own = result_.scans[i];
    std::vector<Eigen::Vector3f> used = std::move(own.used_points_cm);
    const std::size_t points_in = own.points_in, points_used = own.points_used, outliers = own.outliers_replaced;
    own = outcome;
    own.used_points_cm = std::move(used);
    own.points_in = points_in;
    own.points_used = points_used;
    own.outliers_replaced = outliers;
    states_[i].pose = outcome.world_from_points;
  }

  /// What follows the last scan: the rest of the relaxation queue, then loop closing.
  void finish() {
    const std::size_t n = count_;
    if (settings_.mode == MatchingMode::kSimultaneous && !stop_requested() && !queue_.empty()) {
      // What the per-scan budget left: matched now, at most 2 per scan.
      const auto start = Clock::now();
      relax(n - 1, 2 * static_cast<int>(n));
      result_.times.relaxation_s += seconds_since(start);
    }
    if (settings_.mode == MatchingMode::kSimultaneous && stop_requested()) {  // the last relaxation cut short
      result_.interrupted = true;
      result_.scans_matched = n;
      return;
    }
    if (settings_.loops.enabled && settings_.mode != MatchingMode::kSimultaneous) {
      const auto start = Clock::now();
      close_loops();
      result_.times.loop_closure_s += seconds_since(start);
    }
    result_.interrupted = false;
    result_.scans_matched = n;
  }

  MappingResult& result() { return result_; }
  const MappingResult& result() const { return result_; }
  const std::deque<std::size_t>& queue() const { return queue_; }
  void restore_queue(const std::deque<std::size_t>& queue) {
    queue_ = queue;
    queued_.assign(count_, false);
    for (const std::size_t j : queue_) {
      if (j >= count_) throw std::invalid_argument("a queued scan beyond the scans restored");
      queued_[j] = true;
    }
  }
  std::size_t size() const { return count_; }

 private:
  void report(std::size_t done, const std::string& phase) {
    if (progress_) progress_(done, total_, phase);
  }
  bool stop_requested() const { return stop_requested_ && stop_requested_(); }

  /// A scan's clouds before their trees: data, the denser model (if any), the health probe (if any).
  struct Reduced {
    std::vector<Eigen::Vector3f> data, model, probe;
    bool has_model = false, has_probe = false;
  };

  bool voxel_models() const {
    return settings_.dense_models && settings_.model_voxel_cm > 0.0f && settings_.model_voxel_cm < settings_.voxel_cm;
  }

  void prepare_all(const std::vector<Scan>& scans) {
    const std::size_t n = scans.size();
    count_ = n;
    states_.resize(n);
    result_.scans.resize(n);
    // Voxel means are a host computation (the same bits for every backend), one scan per task.
    std::vector<std::vector<Eigen::Vector3f>> voxel_data(n), voxel_model(n);
    if (settings_.reduction == Reduction::kVoxel) {
      const auto start = Clock::now();
      const bool models = voxel_models();
      tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
        voxel_data[i] = voxel_mean_filter(scans[i].points_cm, settings_.voxel_cm);
        if (models) voxel_model[i] = voxel_mean_filter(scans[i].points_cm, settings_.model_voxel_cm);
      });
      result_.times.filter_s += seconds_since(start);
    }
    std::vector<std::vector<Eigen::Vector3f>> data_points(n), models, probes;
    std::vector<bool> has_model(n, false), has_probe(n, false);
    for (std::size_t i = 0; i < n; ++i) {
      Reduced reduced = reduce(i, scans[i], std::move(voxel_data[i]), std::move(voxel_model[i]));
      data_points[i] = std::move(reduced.data);
      has_model[i] = reduced.has_model;
      has_probe[i] = reduced.has_probe;
      if (reduced.has_model) models.push_back(std::move(reduced.model));
      if (reduced.has_probe) probes.push_back(std::move(reduced.probe));
      report(i + 1, "filtering");
    }
    // Every tree at once (the CPU backend builds them in parallel); clouds in scan order.
    const auto start = Clock::now();
    auto data_clouds = backend_.prepare_many(std::move(data_points), settings_.tree);
    auto model_clouds = backend_.prepare_many(std::move(models), settings_.tree);
    auto probe_clouds = backend_.prepare_many(std::move(probes), settings_.tree);
    std::size_t next_model = 0, next_probe = 0;
    for (std::size_t i = 0; i < n; ++i) {
      ScanState& state = states_[i];
      state.cloud = std::move(data_clouds[i]);
      state.model_cloud = has_model[i] ? std::move(model_clouds[next_model++]) : state.cloud;
      state.probe = has_probe[i] ? std::move(probe_clouds[next_probe++]) : state.cloud;
    }
    if (needs_planes()) {
      tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
        states_[i].planes.emplace(states_[i].model_cloud->points(), settings_.plane_cell_cm);
      });
    }
    result_.times.tree_build_s += seconds_since(start);
  }

  bool needs_planes() const {
    return settings_.health.enabled || (settings_.loops.enabled && settings_.loops.information_from_geometry);
  }

  /// One scan as prepare_all prepares it, alone: prepare() builds the tree prepare_many would.
  void prepare_one(const Scan& scan) {
    const std::size_t i = count_++;
    states_.emplace_back();
    result_.scans.emplace_back();
    std::vector<Eigen::Vector3f> voxel_data, voxel_model;
    if (settings_.reduction == Reduction::kVoxel) {
      const auto start = Clock::now();
      voxel_data = voxel_mean_filter(scan.points_cm, settings_.voxel_cm);
      if (voxel_models()) voxel_model = voxel_mean_filter(scan.points_cm, settings_.model_voxel_cm);
      result_.times.filter_s += seconds_since(start);
    }
    Reduced reduced = reduce(i, scan, std::move(voxel_data), std::move(voxel_model));
    const auto start = Clock::now();
    ScanState& state = states_[i];
    state.cloud = backend_.prepare(std::move(reduced.data), settings_.tree);
    state.model_cloud = reduced.has_model ? backend_.prepare(std::move(reduced.model), settings_.tree) : state.cloud;
    state.probe = reduced.has_probe ? backend_.prepare(std::move(reduced.probe), settings_.tree) : state.cloud;
    if (needs_planes()) state.planes.emplace(state.model_cloud->points(), settings_.plane_cell_cm);
    result_.times.tree_build_s += seconds_since(start);
  }

  /// Scan i reduced as the settings say (voxel_data, voxel_model: its voxel means, kVoxel), with its
  /// outcome's and state's starting values.
  Reduced reduce(std::size_t i, const Scan& scan, std::vector<Eigen::Vector3f> voxel_data,
                 std::vector<Eigen::Vector3f> voxel_model) {
    Reduced reduced;
    {
      ScanOutcome& outcome = result_.scans[i];
      outcome.name = scan.name;
      outcome.initial_pose_cm = scan.pose_cm;
      outcome.pose_cm = scan.pose_cm;
      outcome.points_in = scan.size();
      outcome.frames.push_back({scan.pose_cm, 0});
      auto start = Clock::now();
      std::vector<Eigen::Vector3f> points;
      if (settings_.reduction == Reduction::kVoxel) {
        points = std::move(voxel_data);
      } else if (scan.has_slices() && settings_.filter_enabled) {
        SliceFilterResult filtered = backend_.filter_slices(scan, settings_.filter);
        outcome.outliers_replaced = filtered.outliers_replaced;
        points = std::move(filtered.points_cm);
      } else {
        if (!scan.has_slices() && settings_.filter_enabled && !unstructured_noted_) {
          result_.notes.push_back("scans without slice structure: slice filter skipped");
          unstructured_noted_ = true;
        }
        points = thin_unstructured(scan, settings_.unstructured_point_stride);
      }
      // The denser model cloud (see MappingSettings::dense_models); none when it would equal the data.
      std::vector<Eigen::Vector3f> model_points;
      bool dense_model = false;
      if (settings_.reduction == Reduction::kVoxel) {
        dense_model = !voxel_model.empty();
        model_points = std::move(voxel_model);
      } else if (settings_.dense_models && scan.has_slices() && settings_.filter_enabled &&
          settings_.model_slice_stride < settings_.filter.slice_stride) {
        SliceFilterSettings model_filter = settings_.filter;
        model_filter.slice_stride = settings_.model_slice_stride;
        model_points = backend_.filter_slices(scan, model_filter).points_cm;
        dense_model = true;
      } else if (settings_.dense_models && (!scan.has_slices() || !settings_.filter_enabled) &&
                 settings_.unstructured_point_stride > 1) {
        model_points = thin_unstructured(scan, 1);
        dense_model = true;
      }
      result_.times.filter_s += seconds_since(start);
      outcome.points_used = points.size();
      outcome.used_points_cm = points;
      const std::size_t stride = static_cast<std::size_t>(settings_.health.probe_stride);
      if (settings_.health.enabled && stride > 1) {
        for (std::size_t k = 0; k < points.size(); k += stride) reduced.probe.push_back(points[k]);
        reduced.has_probe = true;
      }
      reduced.data = std::move(points);
      if (dense_model) {
        reduced.model = std::move(model_points);
        reduced.has_model = true;
      }
      ScanState& state = states_[i];
      state.odometry = scan.world_from_points();
      state.pose = state.odometry;
      state.points_from_file = rigid_inverse(scan.world_from_points()) * scan.pose_cm;
      outcome.world_from_points = state.pose;
    }
    return reduced;
  }

  const SurfaceNormals* planes_of(std::size_t i) const {
    return states_[i].planes ? &*states_[i].planes : nullptr;
  }

  /// Judges scan i's match (from `start` to its current pose) against `models`.
  void judge(std::size_t i, const Pose& start, std::span<const WorldModel> models) {
    result_.scans[i].health = judge_registration(backend_, *states_[i].probe, states_[i].pose, start, models, icp_,
                                                 settings_.health, 0.0f, planes_of(i));
  }

  void set_pose(std::size_t i, const Pose& world_from_points, const IcpResult& match) {
    states_[i].pose = world_from_points;
    ScanOutcome& outcome = result_.scans[i];
    outcome.pose_cm = world_from_points * states_[i].points_from_file;
    outcome.world_from_points = world_from_points;
    outcome.frames.push_back({outcome.pose_cm, 1});
    outcome.last_match = match;
    outcome.registered = true;
    outcome.failure.clear();
  }

  void mark_failed(std::size_t i, const IcpResult& match) {
    ScanOutcome& outcome = result_.scans[i];
    outcome.registered = false;
    outcome.last_match = match;
    outcome.health = {};
    outcome.failure = std::string(to_string(match.stop)) + " (" + std::to_string(match.pairs) + " pairs)";
  }

  /// World bounds of scan i at its current pose, from its kd-tree's local box (8 corners).
  Bounds3d bounds_of(std::size_t i) const {
    const KdTree& tree = states_[i].model_cloud->tree();
    if (tree.empty()) return {};
    const std::array<Eigen::Vector3f, 2> corners = {tree.bounds_min(), tree.bounds_max()};
    return world_bounds(corners, states_[i].pose);
  }

  /// Scans 0..limit-1 (not i) whose world bounds come within the pair distance of scan i's,
  /// closest scan position first: searching near, dense scans first tightens the pair bound early.
  std::vector<std::size_t> nearby(std::size_t i, std::size_t limit) const {
    const float margin = settings_.icp.max_pair_dist_cm;
    const Bounds3d bounds = bounds_of(i);
    std::vector<std::pair<double, std::size_t>> found;
    for (std::size_t j = 0; j < limit; ++j) {
      if (j == i || !bounds.intersects(bounds_of(j), margin)) continue;
      const double distance = (states_[j].pose.block<3, 1>(0, 3) - states_[i].pose.block<3, 1>(0, 3)).norm();
      found.emplace_back(distance, j);
    }
    std::sort(found.begin(), found.end());
    std::vector<std::size_t> out;
    for (const auto& [distance, j] : found) out.push_back(j);
    return out;
  }

  std::vector<WorldModel> models_of(const std::vector<std::size_t>& indices) const {
    std::vector<WorldModel> models;
    for (std::size_t j : indices) models.push_back({states_[j].model_cloud.get(), states_[j].pose});
    return models;
  }

  /// The models scan i is matched against, for a given pair bound (a metascan is cropped by it).
  using ModelsForBound = std::function<std::vector<WorldModel>(float bound_cm)>;

  /// One match of scan i that starts wide: ICP at `bound_cm` from `start` (no refinement), then the
  /// usual phases from where that ended, judged with the reach of the wide bound. Both runs'
  /// iterations are added to `iterations`.
  struct WideMatch {
    std::optional<IcpResult> fine;  ///< empty: an ICP run failed (`failure` says how)
    RegistrationHealth health;
    std::string failure;
  };
  WideMatch match_from_wide_bound(std::size_t i, const Pose& start, std::span<const WorldModel> models, float bound_cm,
                                  int& iterations) {
    IcpSettings wide = icp_;
    wide.max_pair_dist_cm = bound_cm;
    wide.refine_pair_dist_fraction = 0.0f;
    WideMatch match;
    const IcpResult coarse = register_icp(backend_, *states_[i].cloud, start, models, wide);
    iterations += coarse.iterations();
    if (!coarse.ok()) {
      match.failure = to_string(coarse.stop);
      return match;
    }
    IcpResult fine = register_icp(backend_, *states_[i].cloud, coarse.world_from_data, models, icp_);
    iterations += fine.iterations();
    if (!fine.ok()) {
      match.failure = to_string(fine.stop);
      return match;
    }
    match.health = judge_registration(backend_, *states_[i].probe, fine.world_from_data, start, models, icp_,
                                      settings_.health, bound_cm, planes_of(i));
    match.fine = std::move(fine);
    return match;
  }

  /// Registers scan i from `start` and judges the match. A doubtful one is tried again from the same
  /// start at each wider bound of settings.retry_bound_factors, coarse to fine (match_from_wide_bound),
  /// until one is trusted; a trusted retry replaces the first match, otherwise the first match and
  /// its doubt stay.
  void register_scan(std::size_t i, const Pose& start, const ModelsForBound& models_for) {
    const std::vector<WorldModel> models = models_for(icp_.max_pair_dist_cm);
    const IcpResult match = register_icp(backend_, *states_[i].cloud, start, models, icp_);
    result_.step1_icp_iterations += match.iterations();
    if (!match.ok()) {
      states_[i].pose = start;
      result_.scans[i].pose_cm = start * states_[i].points_from_file;
      result_.scans[i].world_from_points = start;
      mark_failed(i, match);
      return;
    }
    set_pose(i, match.world_from_data, match);
    judge(i, start, models);
    std::string tried;
    for (const float factor : settings_.retry_bound_factors) {
      if (!result_.scans[i].health.doubtful()) return;
      const float bound = factor * icp_.max_pair_dist_cm;
      if (bound > settings_.max_retry_bound_cm) break;
      const std::vector<WorldModel> wide_models = models_for(bound);
      WideMatch retry = match_from_wide_bound(i, start, wide_models, bound, result_.step1_icp_iterations);
      if (!retry.fine) continue;
      if (retry.health.doubtful()) {
        char text[32];
        std::snprintf(text, sizeof text, "%g cm", double(bound));
        tried += (tried.empty() ? "" : ", ") + std::string(text);
        continue;
      }
      set_pose(i, retry.fine->world_from_data, *retry.fine);
      retry.health.retry_bound_cm = bound;
      result_.scans[i].health = retry.health;
      return;
    }
    if (!tried.empty()) result_.scans[i].health.doubt += " (tried again from " + tried + ": still doubtful)";
  }

  /// Step 1 (and the pairwise mode): match scan i against scan i-1 from corrected odometry.
  void match_pairwise(std::size_t i) {
    const Pose odometry_step = rigid_inverse(states_[i - 1].odometry) * states_[i].odometry;
    const Pose start = states_[i - 1].pose * odometry_step;
    states_[i].pose = start;
    register_scan(i, start, [&](float) { return models_of({i - 1}); });
  }

  /// The metascan of scan i at its current (predicted) pose: one kd-tree over the points of the
  /// registered scans near it, as the paper (and slam6D) match against. One tree answers each query
  /// once, where searching every neighbour's own tree in turn costs a search per overlapping scan.
  /// Built in the frame of scan i-1 (`frame`), so its float coordinates stay small wherever the
  /// survey is. Only model points that scan i can reach: inside its box at `at` grown by `grow_cm`. In a
  /// tunnel the nearby scans hold about ten times the points that lie there (docs/benchmarks.md).
  std::shared_ptr<const PreparedCloud> build_metascan(std::size_t i, const Pose& frame, const Pose& at, double grow_cm,
                                                      bool whole_map = false) {
    // whole_map: every other scan near it, earlier or later (judging the final map).
    std::vector<std::size_t> near = nearby(i, whole_map ? count_ : i);
    if (settings_.loops.enabled && !whole_map) {  // recent scans only: a loop is the relaxation's to close
      const std::size_t gap = static_cast<std::size_t>(settings_.loops.min_scan_gap);
      std::erase_if(near, [&](std::size_t j) { return j + gap < i; });
    }
    return build_union(i, near, frame, at, grow_cm);
  }

  /// One kd-tree, in the frame `frame`, of the model points of scans `near` that scan i can reach
  /// at `at`: inside its box grown by `grow_cm`.
  std::shared_ptr<const PreparedCloud> build_union(std::size_t i, const std::vector<std::size_t>& near,
                                                   const Pose& frame, const Pose& at, double grow_cm) {
    const Pose frame_inverse = rigid_inverse(frame);
    std::vector<Eigen::Vector3f> union_points;
    const KdTree& own = states_[i].cloud->tree();
    const std::array<Eigen::Vector3f, 2> corners = {own.bounds_min(), own.bounds_max()};
    const Bounds3d reach = world_bounds(corners, frame_inverse * at);
    const Eigen::Vector3d reach_min = reach.min_cm.array() - grow_cm, reach_max = reach.max_cm.array() + grow_cm;
    // One task per scan, concatenated in the list's order: the same union for any thread count.
    std::vector<std::vector<Eigen::Vector3f>> parts(near.size());
    tbb::parallel_for(std::size_t{0}, near.size(), [&](std::size_t k) {
      const Pose to_frame = frame_inverse * states_[near[k]].pose;
      const Eigen::Matrix3d rotation = to_frame.block<3, 3>(0, 0);
      const Eigen::Vector3d translation = to_frame.block<3, 1>(0, 3);
      for (const Eigen::Vector3f& p : states_[near[k]].model_cloud->points()) {
        const Eigen::Vector3d q = rotation * p.cast<double>() + translation;
        if ((q.array() < reach_min.array()).any() || (q.array() > reach_max.array()).any()) continue;
        parts[k].push_back(q.cast<float>());
      }
    });
    std::size_t total = 0;
    for (const auto& part : parts) total += part.size();
    union_points.reserve(total);
    for (const auto& part : parts) union_points.insert(union_points.end(), part.begin(), part.end());
    return backend_.prepare(std::move(union_points), settings_.tree);
  }

  void match_incremental(std::size_t i) {
    const Pose odometry_step = rigid_inverse(states_[i - 1].odometry) * states_[i].odometry;
    const Pose start = states_[i - 1].pose * odometry_step;
    states_[i].pose = start;
    const Pose frame = states_[i - 1].pose;
    // The metascans made for each bound live until the scan is registered.
    std::vector<std::shared_ptr<const PreparedCloud>> metascans;
    register_scan(i, start, [&](float bound_cm) {
      metascans.push_back(build_metascan(i, frame, start, double(bound_cm) + settings_.metascan_margin_cm));
      return std::vector<WorldModel>{{metascans.back().get(), frame}};
    });
  }

  /// Steps 2 and 3 after scan `newest` arrived: the queue-based relaxation over scans 0..newest,
  /// at most `budget` matches. The queue persists between calls: the new scan goes first (the
  /// caller puts it there, step 2), and what the budget left waits for the next call.
  void relax(std::size_t newest, int budget) {
    const std::size_t max_neighbours = static_cast<std::size_t>(settings_.max_relaxation_neighbours);
    const double grow_cm = double(icp_.max_pair_dist_cm) + settings_.metascan_margin_cm;
    for (int matches = 0; !queue_.empty() && matches < budget && !stop_requested();) {
      const std::size_t current = queue_.front();
      queue_.pop_front();
      queued_[current] = false;
      // The overlapping scans, nearest first (nearby's order), at most max_neighbours of them.
      std::vector<std::size_t> neighbours;
      for (std::size_t j : nearby(current, newest + 1)) {
        if (max_neighbours > 0 && neighbours.size() == max_neighbours) break;
        const WorldModel model{states_[j].model_cloud.get(), states_[j].pose};
        const std::size_t pairs = count_pairs(backend_, *states_[current].cloud, states_[current].pose, model,
                                              settings_.icp.max_pair_dist_cm);
        if (pairs > static_cast<std::size_t>(settings_.min_overlap_pairs)) neighbours.push_back(j);
      }
      if (neighbours.empty()) continue;
      const Pose before = states_[current].pose;
      const auto metascan = build_union(current, neighbours, before, before, grow_cm);
      const std::vector<WorldModel> models{{metascan.get(), before}};
      const IcpResult match = register_icp(backend_, *states_[current].cloud, before, models, relaxation_icp_);
      ++matches;
      ++result_.relaxation_matches;
      ++result_.scans[current].relaxation_matches;
      result_.step3_icp_iterations += match.iterations();
      if (!match.ok()) continue;  // keep the pose it had; a failed relaxation step moves nothing
      set_pose(current, match.world_from_data, match);
      judge(current, before, models);
      const Pose change = rigid_inverse(before) * match.world_from_data;
      const bool moved = translation_norm(change) > settings_.moved_translation_cm ||
                         rotation_angle_deg(change) > settings_.moved_rotation_deg;
      if (!moved) continue;
      for (std::size_t j : neighbours) {
        if (j != 0 && !queued_[j]) {
          queue_.push_back(j);
          queued_[j] = true;
        }
      }
    }
  }

  /// A trusted match of scan j against scan i alone, from j's current pose, at each bound of
  /// settings.loops.bound_factors in turn (a wide bound first, then the usual phases from there).
  /// Empty when none is trusted; `doubt` then says what the last one was judged.
  std::optional<Pose> loop_match(std::size_t i, std::size_t j, std::string& doubt) {
    const std::vector<WorldModel> models = models_of({i});
    const Pose start = states_[j].pose;
    int iterations = 0;  // not Table I's: a loop match is neither step 1 nor step 3
    for (const float factor : settings_.loops.bound_factors) {
      const float bound = factor * icp_.max_pair_dist_cm;
      if (bound > settings_.max_retry_bound_cm) break;
      const WideMatch match = match_from_wide_bound(j, start, models, bound, iterations);
      if (!match.fine) {
        doubt = match.failure;
        continue;
      }
      if (!match.health.doubtful()) return match.fine->world_from_data;
      doubt = match.health.doubt;
    }
    return std::nullopt;
  }

  /// The information of the edge `from` -> `to` (`from` at its current pose, `to` at `to_pose`),
  /// from the geometry of their pairs (registration/match_information.hpp): the probe points of `to` with a partner in
  /// `from`'s model within the pair bound, on a plane of `to`'s own surface. Scaled so that its mean
  /// translation information is the settings' (1 / sigma^2), with a floor of
  /// loops.min_information_fraction of that in every direction: a match that could not see a
  /// direction leaves it to the other edges instead of holding it at its guess.
  Matrix6d edge_information(std::size_t from, std::size_t to, const Pose& to_pose, const SurfaceNormals& to_normals) {
    const ModelPlacement placed{states_[from].model_cloud.get(), rigid_inverse(states_[from].pose) * to_pose};
    const std::vector<NearestPair> nearest = backend_.nearest(*states_[to].probe, {&placed, 1}, SearchMethod::kExact,
                                                              PairingSettings{icp_.max_pair_dist_cm});
    const std::span<const Eigen::Vector3f> points = states_[to].probe->points();
    std::vector<Eigen::Vector3f> paired;
    for (std::size_t k = 0; k < nearest.size(); ++k) {
      if (nearest[k].squared_distance_cm2 >= 0.0f) paired.push_back(points[k]);
    }
    const PoseGraphSettings& graph = settings_.loops.graph;
    const double t = 1.0 / (graph.translation_sigma_cm * graph.translation_sigma_cm);
    const double r = 1.0 / (graph.rotation_sigma_rad * graph.rotation_sigma_rad);
    Eigen::Matrix<double, 6, 1> floor;
    floor << t, t, t, r, r, r;
    floor *= settings_.loops.min_information_fraction;
    const Matrix6d geometry = point_to_plane_information(paired, to_normals);
    const double translation_trace = geometry.topLeftCorner<3, 3>().trace();
    if (!(translation_trace > 0.0)) return Matrix6d::Zero();  // no plane seen: the settings' sigmas
    return geometry * (3.0 * t / translation_trace) + Matrix6d(floor.asDiagonal());
  }

  /// Loops (MappingSettings::loops): candidates by position, each matched, then one relaxation of
  /// the scan graph over the chain of scan-to-scan steps and the loop edges that were trusted.
  void close_loops() {
    const std::size_t n = count_;
    const std::size_t gap = static_cast<std::size_t>(settings_.loops.min_scan_gap);
    if (n <= gap) return;
    std::vector<PoseGraphEdge> edges;
    std::vector<Pose> poses(n);
    for (std::size_t k = 0; k < n; ++k) poses[k] = states_[k].pose;
    // The information of an edge comes from the planes of the scan it ends at.
    const auto planes = [&](std::size_t k) {
      return settings_.loops.information_from_geometry ? planes_of(k) : nullptr;
    };
    for (std::size_t k = 1; k < n; ++k) {
      // A scan left at odometry constrains its neighbours only weakly.
      const bool matched = result_.scans[k].registered && result_.scans[k - 1].registered;
      edges.push_back({k - 1, k, rigid_inverse(poses[k - 1]) * poses[k], matched ? 1.0 : 0.01});
      if (matched && planes(k)) edges.back().information = edge_information(k - 1, k, states_[k].pose, *planes(k));
    }
    const std::size_t chain_edges = edges.size();
    // For each scan, the nearest scan at least `gap` earlier, when near enough. Scans in a row that
    // all have one are one return to a known place: one loop edge for it, from the pair that stands
    // closest (the others see less of each other: a scan in a cross-cut against one in the drive),
    // the next closest tried when a match is not trusted. Several edges of one return would pull
    // the relaxation towards their disagreement.
    struct Candidate {
      std::size_t from, to;
      double distance_cm;
    };
    std::vector<double> driven_cm(n, 0.0);  // along the scan positions, from scan 0
    for (std::size_t k = 1; k < n; ++k) {
      driven_cm[k] = driven_cm[k - 1] + (poses[k].block<3, 1>(0, 3) - poses[k - 1].block<3, 1>(0, 3)).norm();
    }
    std::vector<std::vector<Candidate>> returns;
    for (std::size_t j = gap; j < n; ++j) {
      if (!result_.scans[j].registered) continue;
      Candidate best{n, j, settings_.loops.max_distance_cm};
      for (std::size_t i = 0; i + gap <= j; ++i) {
        if (!result_.scans[i].registered || driven_cm[j] - driven_cm[i] < settings_.loops.min_path_cm) continue;
        const double d = (poses[i].block<3, 1>(0, 3) - poses[j].block<3, 1>(0, 3)).norm();
        if (d < best.distance_cm) best = {i, j, d};
      }
      if (best.from == n) continue;
      if (returns.empty() || returns.back().back().to + 1 != j) returns.emplace_back();
      returns.back().push_back(best);
    }
    for (std::vector<Candidate>& candidates : returns) {
      std::stable_sort(candidates.begin(), candidates.end(),
                       [](const Candidate& a, const Candidate& b) { return a.distance_cm < b.distance_cm; });
      for (const Candidate& candidate : candidates) {
        if (stop_requested()) return;
        LoopClosure loop;
        loop.from = candidate.from;
        loop.to = candidate.to;
        const std::optional<Pose> matched = loop_match(loop.from, loop.to, loop.doubt);
        if (matched) {
          loop.closed = true;
          const Pose moved = rigid_inverse(poses[loop.to]) * *matched;
          loop.gap_before_cm = translation_norm(moved);
          loop.gap_before_deg = rotation_angle_deg(moved);
          edges.push_back({loop.from, loop.to, rigid_inverse(poses[loop.from]) * *matched, 1.0});
          // At the pose the loop match found, not where the chain left the scan.
          if (planes(loop.to)) {
            edges.back().information = edge_information(loop.from, loop.to, *matched, *planes(loop.to));
          }
        }
        result_.loops.push_back(loop);
        if (loop.closed) break;
      }
    }
    if (edges.size() == chain_edges) return;
    const PoseGraphResult relaxed = optimise_pose_graph(poses, edges, 0, settings_.loops.graph);
    for (std::size_t k = 1; k < n; ++k) {
      states_[k].pose = relaxed.poses[k];
      ScanOutcome& outcome = result_.scans[k];
      outcome.world_from_points = relaxed.poses[k];
      outcome.pose_cm = relaxed.poses[k] * states_[k].points_from_file;
      outcome.frames.push_back({outcome.pose_cm, 1});
    }
    // The relaxation moved every scan: each is judged again where it ended, against the map of all
    // scans near it. A scan that looked doubtful against a few recent scans (a corner that sees
    // where the drive began) is then judged against the start too.
    for (std::size_t k = 1; k < n && !stop_requested(); ++k) {
      RegistrationHealth& old = result_.scans[k].health;
      if (!result_.scans[k].registered || !old.judged || old.out_of_reach) continue;
      const Pose& pose = states_[k].pose;
      const auto map = build_metascan(k, pose, pose, double(icp_.max_pair_dist_cm), /*whole_map=*/true);
      const std::vector<WorldModel> models{{map.get(), pose}};
      RegistrationHealth health = judge_registration(backend_, *states_[k].probe, pose, pose, models, icp_,
                                                     settings_.health, 0.0f, planes_of(k));
      health.correction_cm = old.correction_cm;
      health.correction_deg = old.correction_deg;
      health.moved_cm = old.moved_cm;
      health.retry_bound_cm = old.retry_bound_cm;
      health.after_loop_closure = true;
      old = health;
    }
    std::size_t edge = chain_edges;
    for (LoopClosure& loop : result_.loops) {
      if (!loop.closed) continue;
      const Pose wanted = relaxed.poses[loop.from] * edges[edge++].from_to;
      const Pose left = rigid_inverse(relaxed.poses[loop.to]) * wanted;
      loop.gap_after_cm = translation_norm(left);
      loop.gap_after_deg = rotation_angle_deg(left);
    }
  }

  /// Scan i, arrived: its match (the mode's), and for kSimultaneous the relaxation after it (steps 2
  /// and 3, within the per-scan budget).
  void match_scan(std::size_t i) {
    const auto arrived = Clock::now();
    switch (settings_.mode) {
      case MatchingMode::kPairwise: match_pairwise(i); break;
      case MatchingMode::kIncremental: match_incremental(i); break;
      case MatchingMode::kSimultaneous: match_pairwise(i); break;
    }
    result_.times.pairwise_s += seconds_since(arrived);
    if (settings_.mode == MatchingMode::kSimultaneous) {
      const auto start = Clock::now();
      queued_.resize(i + 1, false);  // step 2: the new scan first (no scan before it could queue it)
      queue_.push_front(i);
      queued_[i] = true;
      const int per_scan = settings_.max_relaxation_matches_per_scan;
      relax(i, per_scan > 0 ? per_scan : 4 * static_cast<int>(i + 1));
      result_.times.relaxation_s += seconds_since(start);
    }
    result_.scans[i].match_s = seconds_since(arrived);
    report(i + 1, to_string(settings_.mode));
  }

  const MappingSettings& settings_;
  ComputeBackend& backend_;
  const ProgressCallback& progress_;
  const StopRequested& stop_requested_;
  IcpSettings icp_;  ///< settings.icp with min_pairs capped by the overlap threshold
  IcpSettings relaxation_icp_;  ///< icp_ with step 3's convergence thresholds
  std::size_t count_ = 0;  ///< scans prepared (and, but for the newest, matched)
  std::size_t total_ = 0;  ///< scans expected, for progress
  std::vector<ScanState> states_;
  MappingResult result_;
  std::deque<std::size_t> queue_;  ///< kSimultaneous: scans waiting for a relaxation match
  std::vector<bool> queued_;       ///< queued_[j]: scan j is in queue_
  bool unstructured_noted_ = false;
};

}  // namespace

const char* to_string(MatchingMode mode) {
  switch (mode) {
    case MatchingMode::kPairwise: return "pairwise";
    case MatchingMode::kIncremental: return "incremental";
    case MatchingMode::kSimultaneous: return "simultaneous";
  }
  return "?";
}

MatchingMode parse_matching_mode(const std::string& text) {
  if (text == "pairwise") return MatchingMode::kPairwise;
  if (text == "incremental") return MatchingMode::kIncremental;
  if (text == "simultaneous") return MatchingMode::kSimultaneous;
  throw std::invalid_argument("unknown mode '" + text + "' (expected pairwise, incremental or simultaneous)");
}

const char* to_string(Reduction reduction) {
  switch (reduction) {
    case Reduction::kSlices: return "slices";
    case Reduction::kVoxel: return "voxel";
  }
  return "?";
}

Reduction parse_reduction(const std::string& text) {
  if (text == "slices") return Reduction::kSlices;
  if (text == "voxel") return Reduction::kVoxel;
  throw std::invalid_argument("unknown reduction '" + text + "' (expected slices or voxel)");
}

bool MappingResult::all_registered() const {
  return std::all_of(scans.begin(), scans.end(), [](const ScanOutcome& s) { return s.registered; });
}

std::vector<std::size_t> MappingResult::doubtful() const {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < scans.size(); ++i) {
    if (scans[i].registered && scans[i].health.doubtful()) out.push_back(i);
  }
  return out;
}

void MappingSettings::validate() const {
  filter.validate();
  icp.validate();
  if (tree.bucket_size < 1) throw std::invalid_argument("kd-tree bucket size must be >= 1");
  if (unstructured_point_stride < 1) throw std::invalid_argument("point stride must be >= 1");
  if (model_slice_stride < 1) throw std::invalid_argument("model slice stride must be >= 1");
  if (min_overlap_pairs < 0) throw std::invalid_argument("the overlap threshold must be >= 0 pairs");
  if (max_relaxation_matches_per_scan < 0) throw std::invalid_argument("the relaxation cap must be >= 0");
  if (!(plane_cell_cm > 0.0f) || !std::isfinite(plane_cell_cm)) {
    throw std::invalid_argument("the planes' cell must be a finite length > 0 cm");
  }
  if (!(relaxation_min_step_cm >= 0.0) || !(relaxation_min_step_deg >= 0.0) || !std::isfinite(relaxation_min_step_cm) ||
      !std::isfinite(relaxation_min_step_deg)) {
    throw std::invalid_argument("the relaxation's convergence thresholds must be finite and >= 0");
  }
  if (max_relaxation_neighbours < 0) throw std::invalid_argument("the relaxation's neighbour cap must be >= 0");
  for (const float factor : retry_bound_factors) {
    if (!(factor > 1.0f) || !std::isfinite(factor)) throw std::invalid_argument("retry bound factors must be > 1");
  }
  if (!(max_retry_bound_cm > 0.0f)) throw std::invalid_argument("the widest retry bound must be > 0 cm");
  loops.validate();
  health.validate();
  if (reduction == Reduction::kVoxel && (!(voxel_cm > 0.0f) || !std::isfinite(voxel_cm))) {
    throw std::invalid_argument("the voxel size must be a finite length > 0 cm");
  }
  if (!(model_voxel_cm >= 0.0f) || !std::isfinite(model_voxel_cm)) {
    throw std::invalid_argument("the model voxel size must be a finite length >= 0 cm");
  }
  if (!(metascan_margin_cm >= 0.0) || !std::isfinite(metascan_margin_cm)) {
    throw std::invalid_argument("the metascan margin must be a finite length >= 0 cm");
  }
}

void LoopClosureSettings::validate() const {
  if (min_scan_gap < 2) throw std::invalid_argument("a loop must join scans at least 2 apart");
  if (!(max_distance_cm > 0.0) || !std::isfinite(max_distance_cm)) {
    throw std::invalid_argument("the loop candidates' distance must be a finite length > 0 cm");
  }
  if (!(min_path_cm >= 0.0) || !std::isfinite(min_path_cm)) {
    throw std::invalid_argument("a loop's least drive must be a finite length >= 0 cm");
  }
  for (const float factor : bound_factors) {
    if (!(factor >= 1.0f) || !std::isfinite(factor)) throw std::invalid_argument("loop bound factors must be >= 1");
  }
  if (!(graph.translation_sigma_cm > 0.0) || !(graph.rotation_sigma_rad > 0.0) || graph.max_iterations < 1) {
    throw std::invalid_argument("the pose graph needs sigmas > 0 and at least one iteration");
  }
  if (!(min_information_fraction > 0.0) || !(min_information_fraction <= 1.0)) {
    throw std::invalid_argument("the information floor must be in (0, 1]");
  }
}

MappingResult map_survey(const std::vector<Scan>& scans, const MappingSettings& settings, ComputeBackend& backend,
                         const ProgressCallback& progress, const StopRequested& stop_requested) {
  settings.validate();
  if (scans.empty()) throw std::invalid_argument("the survey holds no scans");
  try {
    return SurveyMatcher(settings, backend, progress, stop_requested).run(scans);
  } catch (const BackendError& e) {
    if (backend.name() == "cpu") throw;
    // The device failed mid-run: match everything again on the CPU, which gives the CPU's poses.
    const std::string failed = backend.name() == "opencl" ? "OpenCL" : backend.name();
    CpuBackend cpu;
    MappingResult result = SurveyMatcher(settings, cpu, progress, stop_requested).run(scans);
    result.backend_note = "CPU backend (TBB), after the " + failed + " failure in the note";
    result.notes.insert(result.notes.begin(),
                        failed + " failed (" + e.what() + "); the survey was matched again on the CPU");
    return result;
  }
}

struct LiveMapper::Impl {
  Impl(const MappingSettings& settings_in, ComputeBackend& backend, StopRequested stop)
      : settings(settings_in), stop_requested(std::move(stop)), matcher(settings, backend, progress, stop_requested) {}
  MappingSettings settings;
  ProgressCallback progress;
  StopRequested stop_requested;
  SurveyMatcher matcher;
};

LiveMapper::LiveMapper(const MappingSettings& settings, ComputeBackend& backend, StopRequested stop_requested) {
  settings.validate();
  impl_ = std::make_unique<Impl>(settings, backend, std::move(stop_requested));
}
LiveMapper::~LiveMapper() = default;
void LiveMapper::add(const Scan& scan) { impl_->matcher.add(scan); }
void LiveMapper::restore(const Scan& scan, const ScanOutcome& outcome) { impl_->matcher.restore(scan, outcome); }
std::vector<std::size_t> LiveMapper::queue() const {
  const auto& queue = impl_->matcher.queue();
  return {queue.begin(), queue.end()};
}
void LiveMapper::restore_queue(const std::vector<std::size_t>& queue) {
  impl_->matcher.restore_queue({queue.begin(), queue.end()});
}
MappingResult& LiveMapper::result() { return impl_->matcher.result(); }
const MappingResult& LiveMapper::result() const { return impl_->matcher.result(); }
void LiveMapper::finish() { impl_->matcher.finish(); }
std::size_t LiveMapper::size() const { return impl_->matcher.size(); }

PoseErrors pose_errors(const std::vector<Pose>& estimated, const std::vector<Pose>& reference) {
  if (estimated.size() != reference.size() || estimated.empty()) {
    throw std::invalid_argument("pose_errors: estimated and reference differ in count or are empty");
  }
  PoseErrors errors;
  const Pose est0 = rigid_inverse(estimated.front());
  const Pose ref0 = rigid_inverse(reference.front());
  const std::size_t n = estimated.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Pose difference = rigid_inverse(ref0 * reference[i]) * (est0 * estimated[i]);
    const double t = translation_norm(difference), r = rotation_angle_deg(difference);
    errors.mean_translation_cm += t / static_cast<double>(n);
    errors.mean_rotation_deg += r / static_cast<double>(n);
    errors.max_translation_cm = std::max(errors.max_translation_cm, t);
    errors.max_rotation_deg = std::max(errors.max_rotation_deg, r);
    if (i == 0) continue;
    const Pose relative_ref = rigid_inverse(reference[i - 1]) * reference[i];
    const Pose relative_est = rigid_inverse(estimated[i - 1]) * estimated[i];
    const Pose relative_difference = rigid_inverse(relative_ref) * relative_est;
    const double rt = translation_norm(relative_difference), rr = rotation_angle_deg(relative_difference);
    errors.mean_relative_translation_cm += rt / static_cast<double>(n - 1);
    errors.mean_relative_rotation_deg += rr / static_cast<double>(n - 1);
    errors.max_relative_translation_cm = std::max(errors.max_relative_translation_cm, rt);
    errors.max_relative_rotation_deg = std::max(errors.max_relative_rotation_deg, rr);
    errors.path_length_cm += translation_norm(relative_ref);
  }
  return errors;
}

}  // namespace minemap
