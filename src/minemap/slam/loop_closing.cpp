#include "minemap/slam/loop_closing.hpp"

#include <algorithm>
#include <cstdio>
#include <span>

#include "minemap/registration/match_information.hpp"
#include "minemap/slam/motion_model.hpp"

namespace minemap::detail {
namespace {

/// The drive from scan 0 to each scan, along the scan positions as they stand (cm).
std::vector<double> driven_cm(const SurveyState& state) {
  const auto position = [&](std::size_t k) { return state.pose(k).block<3, 1>(0, 3); };
  std::vector<double> driven(state.size(), 0.0);
  for (std::size_t k = 1; k < state.size(); ++k) driven[k] = driven[k - 1] + (position(k) - position(k - 1)).norm();
  return driven;
}

}  // namespace

bool LoopClosing::geometric(const SurveyState& state, std::size_t k) const {
  return settings_.loops.information_from_geometry && state.prepared(k).planes.has_value();
}

std::vector<PoseGraphEdge> LoopClosing::chain(SurveyState& state, const RunControl& control) const {
  std::vector<PoseGraphEdge> edges;
  for (std::size_t k = 1; k < state.size(); ++k) {
    control.report(k + 1, "pose graph");
    // A scan left at odometry constrains its neighbours only weakly.
    const bool matched = state.registered(k) && state.registered(k - 1);
    edges.push_back({k - 1, k, rigid_inverse(state.pose(k - 1)) * state.pose(k), matched ? 1.0 : 0.01});
    if (matched && geometric(state, k)) edges.back().information = edge_information(state, k - 1, k, state.pose(k));
    state.release_over_budget();  // a long survey's memory bound (each scan read back once here)
  }
  return edges;
}

LoopClosing::Return LoopClosing::next_return(const SurveyState& state, const std::vector<Pose>& guess,
                                             const std::vector<double>& driven, std::size_t first) const {
  // For each scan, the nearest scan at least `gap` earlier, when near enough. Scans in a row that
  // all have one are one return to a known place: one loop edge for it, from the pair that stands
  // closest (the others see less of each other: a scan in a cross-cut against one in the drive),
  // the next closest tried when a match is not trusted. Several edges of one return would pull
  // the relaxation towards their disagreement.
  const std::size_t n = state.size();
  const std::size_t gap = static_cast<std::size_t>(settings_.loops.min_scan_gap);
  const auto position = [&](std::size_t k) { return guess[k].block<3, 1>(0, 3); };
  Return found;
  found.end = n;
  for (std::size_t j = std::max(first, gap); j < n; ++j) {
    found.end = j + 1;
    if (!state.registered(j)) {
      if (found.candidates.empty()) continue;
      found.end = j;
      break;
    }
    Candidate best{n, j, settings_.loops.max_distance_cm};
    for (std::size_t i = 0; i + gap <= j; ++i) {
      if (!state.registered(i) || driven[j] - driven[i] < settings_.loops.min_path_cm) continue;
      const double d = (position(i) - position(j)).norm();
      if (d < best.distance_cm) best = {i, j, d};
    }
    const double longest = settings_.loops.max_return_path_cm;
    if (best.from == n || (!found.candidates.empty() && longest > 0.0 &&
                           driven[j] - driven[found.candidates.front().to] > longest)) {
      if (found.candidates.empty()) continue;
      found.end = j;
      break;
    }
    found.candidates.push_back(best);
  }
  std::stable_sort(found.candidates.begin(), found.candidates.end(),
                   [](const Candidate& a, const Candidate& b) { return a.distance_cm < b.distance_cm; });
  return found;
}

std::optional<Pose> LoopClosing::loop_match(const SurveyState& state, std::size_t i, std::size_t j, const Pose& start,
                                            std::string& doubt, bool& converged) const {
  const std::size_t model[] = {i};
  std::vector<WorldModel> models = state.models_of(model);
  std::shared_ptr<const PreparedCloud> visit;  // a narrow-field timed sweep's: the sweeps around i, one tree
  const auto timed = [&](std::size_t k) { return state.prepared(k).sweep_s > 0.0; };
  if (settings_.loops.visit_sweeps > 0 && timed(i) && timed(j) &&
      narrow_field(state, j, settings_.motion.sweep_spring_max_field_deg)) {
    const std::size_t half = static_cast<std::size_t>(settings_.loops.visit_sweeps);
    const std::size_t gap = static_cast<std::size_t>(settings_.loops.min_scan_gap);
    std::vector<std::size_t> near;  // i first, then outwards: the local map keeps the first one's point in a cell
    const auto add = [&](std::size_t k) {
      if (k < state.size() && k + gap <= j && state.registered(k) && timed(k)) near.push_back(k);
    };
    for (std::size_t d = 0; d <= half; ++d) {
      if (d <= i) add(i - d);
      if (d > 0) add(i + d);
    }
    const float bound_cm = registration_.icp().max_pair_dist_cm;
    float widest_cm = bound_cm;  // one tree for every bound the match tries: cropped to the widest's reach
    for (const float factor : settings_.loops.bound_factors) {
      widest_cm = std::max(widest_cm, std::min(factor * bound_cm, float(settings_.max_retry_bound_cm)));
    }
    visit = local_map_.union_of(state, j, near, state.pose(i), start, double(widest_cm) + settings_.metascan_margin_cm,
                                settings_.motion.local_map_cell_cm);
    models = {{visit.get(), state.pose(i)}};
  }
  for (const float factor : settings_.loops.bound_factors) {
    const float bound = factor * registration_.icp().max_pair_dist_cm;
    if (bound > settings_.max_retry_bound_cm) break;
    // Its iterations are not Table I's: a loop match is neither step 1 nor step 3.
    const WideMatch match = registration_.match_from_wide_bound(state.prepared(j), start, models, bound);
    if (!match.fine) {
      doubt = match.failure;
      continue;
    }
    if (!match.health.doubtful()) return match.fine->world_from_data;
    doubt = match.health.doubt;
    converged = true;
  }
  return std::nullopt;
}

/// The probe points of `to` with a partner in `from`'s model within the pair bound, on a plane of
/// `to`'s own surface, give the point-to-plane information; scaled so that its mean translation
/// information is the settings' (1 / sigma^2), with a floor of loops.min_information_fraction of
/// that in every direction: a match that could not see a direction leaves it to the other edges
/// instead of holding it at its guess.
Matrix6d LoopClosing::edge_information(const SurveyState& state, std::size_t from, std::size_t to,
                                       const Pose& to_pose) const {
  const PreparedScan& target = state.prepared(to);
  const ModelPlacement placed{state.prepared(from).model_cloud.get(), rigid_inverse(state.pose(from)) * to_pose};
  const std::vector<NearestPair> nearest = backend_.nearest(*target.probe, {&placed, 1}, SearchMethod::kExact,
                                                            PairingSettings{registration_.icp().max_pair_dist_cm});
  const std::span<const Eigen::Vector3f> points = target.probe->points();
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
  const Matrix6d geometry = point_to_plane_information(paired, *target.planes);
  const double translation_trace = geometry.topLeftCorner<3, 3>().trace();
  if (!(translation_trace > 0.0)) return Matrix6d::Zero();  // no plane seen: the settings' sigmas
  return geometry * (3.0 * t / translation_trace) + Matrix6d(floor.asDiagonal());
}

void LoopClosing::doubt_misclosure(SurveyState& state, const LoopClosure& loop) const {
  const double most = settings_.loops.max_misclosure_fraction;
  if (!(most > 0.0) || !(loop.misclosure_fraction() > most)) return;
  RegistrationHealth health = state.health(loop.to);
  if (!health.judged || health.doubtful()) return;
  char text[360];
  std::snprintf(text, sizeof text,
                "the loop from %s closed %.0f cm / %.1f deg apart after %.1f m of drive (%.2g %%, more than %.2g %%): "
                "the scans between were that far off, and the relaxation only spread it; check them",
                state.outcome(loop.from).name.c_str(), loop.gap_before_cm, loop.gap_before_deg, loop.path_cm / 100.0,
                100.0 * loop.misclosure_fraction(), 100.0 * most);
  health.doubt = text;
  state.judged(loop.to, std::move(health));
}

std::optional<Pose> LoopClosing::agreeing(const Pose& matched, const Pose& start, LoopClosure& loop,
                                          bool& converged) const {
  const double most = settings_.loops.max_misclosure_fraction;
  const Pose moved = rigid_inverse(start) * matched;
  if (!(most > 0.0) || !(translation_norm(moved) > most * loop.path_cm)) return matched;
  char text[300];
  std::snprintf(text, sizeof text,
                "the match moved it %.0f cm / %.1f deg from where the loops closed before put it, more than %.2g %% "
                "of the %.0f m of drive between (a corridor's walls fit as well metres along it)",
                translation_norm(moved), rotation_angle_deg(moved), 100.0 * most, loop.path_cm / 100.0);
  loop.doubt = text;
  converged = true;
  return std::nullopt;
}

std::optional<Pose> LoopClosing::within_turn(const Pose& matched, const Pose& start, bool carried, LoopClosure& loop,
                                             bool& converged) const {
  const double per_100m = settings_.loops.max_turn_deg_per_100m;
  const double most_deg = per_100m * loop.path_cm / 10000.0;
  const double turn_deg = rotation_angle_deg(rigid_inverse(start) * matched);
  if (!(per_100m > 0.0) || !(turn_deg > most_deg)) return matched;
  char text[300];
  std::snprintf(text, sizeof text,
                "the match turned it %.1f deg from where %s put it, more than %g deg per 100 m over the %.0f m of "
                "drive between (%.1f deg): a corridor seen the other way, or a look-alike place",
                turn_deg, carried ? "the loops closed before" : "the chain", per_100m, loop.path_cm / 100.0, most_deg);
  loop.doubt = text;
  converged = true;
  return std::nullopt;
}

void LoopClosing::carry(std::vector<Pose>& guess, std::size_t from, std::size_t to, const Pose& from_to) {
  // Orthonormalised: rigid_inverse transposes, so a rotation part a round-off away from orthonormal
  // comes back from it scaled the wrong way, and the move passes that on to every later guess. Loop
  // after loop the error compounds (it doubled or more per loop): a 2 000-scan patrol's guesses had
  // rotation parts scaled by 4 % after 43 loops, 30 % after 60, and every later return was paired
  // and started wrongly (docs/scaling.md, "Loops at scale").
  const Pose move = orthonormalised(Pose(guess[from] * from_to) * rigid_inverse(guess[to]));
  for (std::size_t k = to; k < guess.size(); ++k) guess[k] = move * guess[k];
}

void LoopClosing::doubt_unclosed_return(SurveyState& state, const LoopClosure& loop) const {
  RegistrationHealth health = state.health(loop.to);
  if (!health.judged || health.doubtful()) return;
  health.doubt = "the drive came back near " + state.outcome(loop.from).name +
                 ", and no loop match there was trusted (" + loop.doubt +
                 "): the drift over the loop stays in the map, unmeasured; check it, or give closer starts";
  state.judged(loop.to, std::move(health));
}

void LoopClosing::judge_again(SurveyState& state, const RunControl& control) const {
  // The relaxation moved every scan: each is judged again where it ended, against the scans near it
  // (loops.judge_max_visits, judge_max_scans). A scan that looked doubtful against a few recent
  // scans (a corner that sees where the drive began) is then judged against the start too. The
  // neighbours are searched in trees kept from scan to scan (JudgingClouds: one per block of 64
  // in a row, the block's scans that are not neighbours left out of its search, else one per
  // scan), not one tree over their union built for each judged scan: the judge's one pass over a
  // scan's probe points never paid back that build (72 % of the judging).
  JudgingClouds clouds(local_map_);
  const std::shared_ptr<const PreparedCloud> nothing = backend_.prepare({}, settings_.tree);
  for (std::size_t k = 1; k < state.size() && !control.stop_requested(); ++k) {
    control.report(k + 1, "judging");
    const RegistrationHealth& old = state.health(k);
    // A doubt about how the match got there (out of reach) or about the motion (a turn the
    // surfaces could not pin) is not cleared by a fit where the relaxation left the scan.
    if (!state.registered(k) || !old.judged || old.out_of_reach || old.failed == HealthTest::kUnpinnedTurn) continue;
    const Pose& pose = state.pose(k);
    std::vector<WorldModel> models = clouds.models(state, local_map_.judging_scans(state, k, pose), k);
    if (models.empty()) models.push_back({nothing.get(), pose});  // judged, and nothing pairs
    RegistrationHealth health = registration_.judge(state.prepared(k), pose, pose, models);
    health.correction_cm = old.correction_cm;
    health.correction_deg = old.correction_deg;
    health.moved_cm = old.moved_cm;
    health.retry_bound_cm = old.retry_bound_cm;
    health.recovered_inliers = old.recovered_inliers;
    health.note = old.note;  // how its match was confirmed, recovered or kept: still how it got there
    health.after_loop_closure = true;
    state.judged(k, std::move(health));
    clouds.forget_unused(k);
    state.release_over_budget();
  }
}

std::vector<LoopClosure> LoopClosing::close(SurveyState& state, RunControl& control,
                                            std::vector<PoseGraphEdge>* graph) const {
  std::vector<LoopClosure> loops;
  const std::size_t n = state.size();
  if (n <= static_cast<std::size_t>(settings_.loops.min_scan_gap)) return loops;
  std::vector<Pose> poses(n);
  for (std::size_t k = 0; k < n; ++k) poses[k] = state.pose(k);
  const std::vector<double> driven = driven_cm(state);  // as the chain left the scans
  // Where the loops closed so far put the scans: each closed edge moves its later scan, and every
  // scan after it, rigidly to where the match found it, so that the next return is looked for (and
  // its match started) where the drive really is. Over a patrol of many laps the chain alone drifts
  // metres from lap to lap, and its later laps would be paired with the wrong places.
  std::vector<Pose> guess = poses;
  std::vector<PoseGraphEdge> loop_edges;  // the loops' edges; the chain's come first in the graph
  std::vector<LoopClosure> unclosed_returns;  // the first converged, untrusted candidate of each
  const RunControl::Stopwatch matching;
  for (std::size_t first = 0; first < n;) {
    const Return found = next_return(state, guess, driven, first);
    first = found.end;
    control.report(first, "loop matches");
    std::optional<LoopClosure> unclosed;
    for (const Candidate& candidate : found.candidates) {
      if (control.stop_requested()) return loops;
      LoopClosure loop;
      loop.from = candidate.from;
      loop.to = candidate.to;
      loop.path_cm = driven[loop.to] - driven[loop.from];
      // The match starts where the guess puts `to` against `from` (in the state's frame, where
      // `from`'s model stands); the chain's own pose while no loop has moved one of them.
      const bool carried = guess[loop.from] != poses[loop.from] || guess[loop.to] != poses[loop.to];
      const Pose start = carried ? Pose(poses[loop.from] * rigid_inverse(guess[loop.from]) * guess[loop.to])
                                 : poses[loop.to];
      bool converged = false;
      std::optional<Pose> matched = loop_match(state, loop.from, loop.to, start, loop.doubt, converged);
      if (matched) matched = within_turn(*matched, start, carried, loop, converged);
      if (matched && carried) matched = agreeing(*matched, start, loop, converged);
      if (!matched && converged && !unclosed) unclosed = loop;
      if (matched) {
        loop.closed = true;
        const Pose moved = rigid_inverse(poses[loop.to]) * *matched;  // against the chain
        loop.gap_before_cm = translation_norm(moved);
        loop.gap_before_deg = rotation_angle_deg(moved);
        const Pose from_to = rigid_inverse(poses[loop.from]) * *matched;
        loop_edges.push_back({loop.from, loop.to, from_to, 1.0});
        // At the pose the loop match found, not where the chain left the scan.
        if (geometric(state, loop.to)) {
          loop_edges.back().information = edge_information(state, loop.from, loop.to, *matched);
        }
        carry(guess, loop.from, loop.to, from_to);
      }
      loops.push_back(loop);
      state.release_over_budget();
      if (loop.closed) break;
    }
    if (unclosed && !loops.back().closed) unclosed_returns.push_back(*unclosed);
  }
  control.times().loop_matches_s += matching.seconds();
  // After the relaxation (if any) and its judging: a return whose matches converged but none was
  // trusted leaves its drift in the map, and the run says so.
  if (loop_edges.empty()) {
    for (const LoopClosure& loop : unclosed_returns) doubt_unclosed_return(state, loop);
    return loops;
  }
  // The chain only now that a loop closed: its information pairs every scan with the one before
  // (each model's kd-tree built for it), the state unchanged by the loop matches (they place nothing).
  std::vector<PoseGraphEdge> edges = control.timed(&StageTimes::loop_graph_steps_s, [&] { return chain(state, control); });
  const std::size_t chain_edges = edges.size();
  edges.insert(edges.end(), loop_edges.begin(), loop_edges.end());
  const PoseGraphResult relaxed = control.timed(&StageTimes::loop_solve_s, [&] {
    return optimise_pose_graph(poses, edges, 0, settings_.loops.graph);
  });
  if (graph) *graph = edges;
  for (std::size_t k = 1; k < n; ++k) state.place(k, relaxed.poses[k]);
  control.timed(&StageTimes::loop_judging_s, [&] { judge_again(state, control); });
  std::size_t edge = chain_edges;
  for (LoopClosure& loop : loops) {
    if (!loop.closed) continue;
    const Pose wanted = relaxed.poses[loop.from] * edges[edge++].from_to;
    const Pose left = rigid_inverse(relaxed.poses[loop.to]) * wanted;
    loop.gap_after_cm = translation_norm(left);
    loop.gap_after_deg = rotation_angle_deg(left);
    doubt_misclosure(state, loop);
  }
  for (const LoopClosure& loop : unclosed_returns) doubt_unclosed_return(state, loop);
  return loops;
}

}  // namespace minemap::detail
