#include "minemap/slam/control_tie.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <numbers>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <stdexcept>

#include "minemap/core/error.hpp"
#include "minemap/io/formats.hpp"
#include "minemap/registration/horn.hpp"

namespace minemap {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

/// One observation of a control point, ready for the graph.
struct Observed {
  std::size_t scan = 0;
  std::size_t point = 0;
  Eigen::Vector3d in_points_cm = Eigen::Vector3d::Zero();  ///< the observed point, scan's points frame
  Eigen::Vector3d known_cm = Eigen::Vector3d::Zero();      ///< where it is: grid-local, survey axes
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();    ///< of known_cm (cm^2, survey axes)
};

/// The spread of the control points in `use` that the survey observes (each once, about their mean):
/// its singular values (cm) say how far the points are from one line, V's first column is the line.
Eigen::JacobiSVD<Eigen::MatrixXd> spread_of(const std::vector<Observed>& observed, const std::vector<bool>& use) {
  std::map<std::size_t, Eigen::Vector3d> known;  // each point used, once
  for (const Observed& ob : observed) {
    if (use[ob.point]) known.emplace(ob.point, ob.known_cm);
  }
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& [point, position] : known) mean += position / static_cast<double>(known.size());
  Eigen::MatrixXd centred(static_cast<Eigen::Index>(known.size()), 3);
  Eigen::Index row = 0;
  for (const auto& [point, position] : known) centred.row(row++) = (position - mean).transpose();
  return Eigen::JacobiSVD<Eigen::MatrixXd>(centred, Eigen::ComputeFullV);
}

/// The grid's axes as the survey's: survey = axes * grid.
Eigen::Matrix3d grid_axes(bool survey_3dtk) {
  if (!survey_3dtk) return Eigen::Matrix3d::Identity();
  Eigen::Matrix3d axes;
  axes << 0, -1, 0,  // x_3dtk = -north
      0, 0, 1,       // y_3dtk = height
      1, 0, 0;       // z_3dtk = east
  return axes;
}

Eigen::Vector3d placed(const Pose& pose, const Eigen::Vector3d& point) {
  return pose.block<3, 3>(0, 0) * point + pose.block<3, 1>(0, 3);
}

/// d(T Exp(dx) p)/d(dx) at dx = 0: [R, -R [p]x].
Eigen::Matrix<double, 3, 6> point_jacobian(const Pose& pose, const Eigen::Vector3d& p) {
  Eigen::Matrix<double, 3, 6> jacobian;
  jacobian.leftCols<3>() = pose.block<3, 3>(0, 0);
  jacobian.rightCols<3>() = -pose.block<3, 3>(0, 0) * skew(p);
  return jacobian;
}

[[noreturn]] void fail(const io::ControlFile& control, const std::string& message) {
  throw InputError(FileLocation{control.path, 0, -1}, message, InputProblem::kEmpty);
}

}  // namespace

ScanSigma scan_sigma(const ScanOutcome& scan) {
  ScanSigma sigma;
  if (!scan.covariance) return sigma;
  const Eigen::Matrix3d r = scan.world_from_points.block<3, 3>(0, 0);
  const Eigen::Matrix3d translation = r * scan.covariance->topLeftCorner<3, 3>() * r.transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> axes(translation);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> turns(Eigen::Matrix3d(scan.covariance->bottomRightCorner<3, 3>()));
  for (int a = 0; a < 3; ++a) sigma.axes_cm[a] = std::sqrt(std::max(0.0, axes.eigenvalues()[2 - a]));
  sigma.rotation_deg = std::sqrt(std::max(0.0, turns.eigenvalues()[2])) * 180.0 / std::numbers::pi;
  return sigma;
}

Eigen::Vector3d grid_to_survey_axes(const Eigen::Vector3d& grid, bool survey_3dtk) {
  return grid_axes(survey_3dtk) * grid;
}

Eigen::Vector3d survey_axes_to_grid(const Eigen::Vector3d& survey, bool survey_3dtk) {
  return grid_axes(survey_3dtk).transpose() * survey;
}

void tie_to_control(MappingResult& result, const io::ControlFile& control, bool survey_3dtk,
                    const ControlSettings& settings, const PoseGraphSettings& graph_settings) {
  const std::size_t n = result.scans.size();
  if (result.graph.empty() && n > 1) {
    throw std::invalid_argument("tie_to_control: the run kept no pose graph (ControlSettings::keep_graph)");
  }
  std::vector<std::string> names;
  std::map<std::string, std::size_t> scan_index;
  for (std::size_t k = 0; k < n; ++k) {
    names.push_back(result.scans[k].name);
    scan_index.emplace(result.scans[k].name, k);
  }
  io::check_control_scans(control, names);

  // The observations in the survey's axes, relative to the grid's local origin.
  const Eigen::Matrix3d axes = grid_axes(survey_3dtk);
  const Eigen::Vector3d up = axes * Eigen::Vector3d::UnitZ();
  std::vector<Observed> observed;
  std::set<std::size_t> points_observed;
  Eigen::Vector3d sum_cm = Eigen::Vector3d::Zero();
  for (const io::ControlObservation& o : control.observations) {
    const io::ControlPoint& point = control.points[o.point];
    const std::size_t k = scan_index.at(o.scan);
    const ScanOutcome& scan = result.scans[k];
    const Pose points_from_file = rigid_inverse(scan.world_from_points) * scan.pose_cm;
    Observed ob;
    ob.scan = k;
    ob.point = o.point;
    const bool station = o.kind == io::ControlObservation::Kind::kStation;
    ob.in_points_cm = placed(points_from_file, station ? Eigen::Vector3d::Zero() : o.in_scan_cm);
    // A station's scanner stood its instrument height above the mark, vertically.
    ob.known_cm = axes * (100.0 * point.grid_m) + (station ? o.instrument_height_cm : 0.0) * up;
    const double h2 = 1e4 * point.sigma_horizontal_m * point.sigma_horizontal_m;
    const double v2 = 1e4 * point.sigma_vertical_m * point.sigma_vertical_m;
    ob.covariance = axes * Eigen::Vector3d(h2, h2, v2).asDiagonal() * axes.transpose();
    sum_cm += ob.known_cm;
    points_observed.insert(o.point);
    observed.push_back(ob);
  }
  if (points_observed.size() < 3) {
    fail(control, "the survey's scans observe " + std::to_string(points_observed.size()) +
                      " control point(s): a tie needs at least 3, not on one line");
  }
  // The grid's local origin: the observations' mean on io's 100 m grid, so the poses stay small.
  Eigen::Vector3d origin = sum_cm / static_cast<double>(observed.size());
  for (int a = 0; a < 3; ++a) origin[a] = std::round(origin[a] / io::kLocalOriginGrid_cm) * io::kLocalOriginGrid_cm;
  for (Observed& ob : observed) ob.known_cm -= origin;
  // Three points in a line leave the roll about it free.
  if (spread_of(observed, std::vector<bool>(control.points.size(), true)).singularValues()[1] < 1.0) {
    // cm: within a centimetre of one line
    fail(control, "the " + std::to_string(points_observed.size()) +
                      " control points observed lie on one line: a tie needs 3 not in a line");
  }

  // 1. Helmert: the map as matched, moved rigidly onto the control (Horn, weighted by the sigmas).
  std::vector<Pose> poses(n);
  for (std::size_t k = 0; k < n; ++k) poses[k] = result.scans[k].world_from_points;
  // Horn over the observations of the points in `use`, each weighted by its sigma.
  const auto helmert_of = [&](const std::vector<bool>& use) {
    double total_weight = 0.0;
    std::size_t count = 0;
    for (const Observed& ob : observed) {
      if (!use[ob.point]) continue;
      total_weight += 3.0 / ob.covariance.trace();
      ++count;
    }
    PairSums sums;
    for (const Observed& ob : observed) {
      if (!use[ob.point]) continue;
      const double w = (3.0 / ob.covariance.trace()) * static_cast<double>(count) / total_weight;
      const Eigen::Vector3d p = placed(poses[ob.scan], ob.in_points_cm);
      sums.count += 1.0;
      sums.weight += w;
      sums.sum_data += w * p;
      sums.sum_model += w * ob.known_cm;
      sums.sum_data_model += w * p * ob.known_cm.transpose();
    }
    return horn_transform(sums);
  };
  const std::optional<Pose> helmert = helmert_of(std::vector<bool>(control.points.size(), true));
  if (!helmert) fail(control, "the control points give no rigid transform (Horn's method failed on them)");
  std::vector<Pose> rigid(n);
  for (std::size_t k = 0; k < n; ++k) rigid[k] = orthonormalised(*helmert * poses[k]);

  // 2. The graph with the control as priors, no scan fixed.
  std::vector<bool> used(control.points.size(), true);
  const auto priors_of = [&](const std::vector<bool>& use) {
    std::vector<PoseGraphPrior> priors;
    for (const Observed& ob : observed) {
      if (!use[ob.point]) continue;
      priors.push_back({ob.scan, ob.in_points_cm, ob.known_cm, ob.covariance.inverse()});
    }
    return priors;
  };
  // Damped (Levenberg-Marquardt): without a point, the rest may pin the roll about their line only
  // weakly, and a Gauss-Newton step along it turns the map by anything (a loop whose last station
  // is its first: 33 m off).
  const auto adjust = [&](const std::vector<bool>& use, std::vector<Pose> start,
                          std::span<const PoseGraphRotationPrior> hold = {}) {
    const std::vector<PoseGraphPrior> priors = priors_of(use);
    PoseGraphSettings damped = graph_settings;
    damped.damped = true;
    damped.max_iterations = std::max(damped.max_iterations, 50);
    return optimise_pose_graph(std::move(start), result.graph, priors, hold, kNoFixedPose, damped).poses;
  };
  // Level where the control cannot tell (ControlSettings::level_sigma_deg): control points nearly
  // in a line (a straight drive's stations; a loop's, one left out for the blunder test) leave the
  // map's roll about that line all but free. The tie then keeps the map's own vertical about it (the
  // survey frame's up stays the grid's up, to this sigma): a prior at the scan nearest the control's
  // middle on the rotation about the points' principal axis only. Left free, the roll came out as
  // the noise had it (one compiler's map 14.8 cm, another's 21.4 cm mean off in the grid, 59 % of the
  // scans outside their 95 % ellipsoids); points that pin the roll outweigh it by far (5 mm over a
  // few metres of spread is 0.1 deg).
  std::size_t middle_scan = 0;
  {
    Eigen::Vector3d middle = Eigen::Vector3d::Zero();
    for (const Observed& ob : observed) middle += ob.known_cm / static_cast<double>(observed.size());
    for (std::size_t k = 1; k < n; ++k) {
      if ((rigid[k].block<3, 1>(0, 3) - middle).norm() < (rigid[middle_scan].block<3, 1>(0, 3) - middle).norm()) {
        middle_scan = k;
      }
    }
  }
  const auto level_of = [&](const std::vector<bool>& use, const std::vector<Pose>& at) {
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd = spread_of(observed, use);
    const Eigen::Vector3d axis = svd.matrixV().col(0).normalized();
    // The tie's turn at the middle scan, and what brings the map's up back to the grid's about `axis`.
    const Eigen::Matrix3d turn = at[middle_scan].block<3, 3>(0, 0) * poses[middle_scan].block<3, 3>(0, 0).transpose();
    const Eigen::Vector3d tilted = turn * up - axis * axis.dot(turn * up);
    const Eigen::Vector3d level = up - axis * axis.dot(up);
    double angle = 0.0;
    if (tilted.norm() > 1e-9 && level.norm() > 1e-9) {
      angle = std::atan2(axis.dot(tilted.cross(level)), tilted.dot(level));
    }
    const Eigen::Matrix3d known_rotation =
        Eigen::AngleAxisd(angle, axis).toRotationMatrix() * at[middle_scan].block<3, 3>(0, 0);
    const double sigma_rad = settings.level_sigma_deg * std::numbers::pi / 180.0;
    return std::vector<PoseGraphRotationPrior>{{middle_scan, known_rotation, axis, 1.0 / (sigma_rad * sigma_rad)}};
  };
  std::vector<Pose> adjusted = adjust(used, rigid, level_of(used, rigid));

  // 3. Blunders: each point predicted by the map tied to the others (only where the others still
  // pin the map: 3 points at least besides it).
  const double scale2 = settings.sigma_scale * settings.sigma_scale;
  std::vector<ControlResidual> residuals(control.points.size());
  for (std::size_t p = 0; p < control.points.size(); ++p) {
    residuals[p].point = control.points[p].name;
    residuals[p].sigma_horizontal_m = control.points[p].sigma_horizontal_m;
    residuals[p].sigma_vertical_m = control.points[p].sigma_vertical_m;
  }
  for (const Observed& ob : observed) residuals[ob.point].scans.push_back(ob.scan);
  const auto first_observation = [&](std::size_t point) -> const Observed& {
    for (const Observed& ob : observed) {
      if (ob.point == point) return ob;
    }
    throw std::logic_error("tie_to_control: a point without observation");
  };
  for (;;) {
    std::vector<std::size_t> in_use;
    for (const std::size_t p : points_observed) {
      if (used[p]) in_use.push_back(p);
    }
    if (in_use.size() < 4) break;
    // Without a point, the rest may leave the roll about their line free (a loop whose last station
    // is its first): the prediction is made with the map's orientation held as the whole tie has it.
    std::size_t worst = control.points.size();
    double worst_sigmas = 0.0;
    Eigen::Vector3d worst_error = Eigen::Vector3d::Zero();
    for (const std::size_t p : in_use) {
      std::vector<bool> others = used;
      others[p] = false;
      const std::vector<PoseGraphRotationPrior> held = level_of(others, adjusted);
      const std::vector<Pose> without = adjust(others, adjusted, held);
      const Observed& ob = first_observation(p);
      const std::vector<PoseGraphPrior> priors = priors_of(others);
      const std::size_t node[] = {ob.scan};
      const Matrix6d covariance =
          scale2 * pose_graph_covariances(without, result.graph, priors, held, kNoFixedPose, graph_settings, node)[0];
      const Eigen::Matrix<double, 3, 6> jacobian = point_jacobian(without[ob.scan], ob.in_points_cm);
      const Eigen::Matrix3d c = jacobian * covariance * jacobian.transpose() + ob.covariance;
      const Eigen::Vector3d error = placed(without[ob.scan], ob.in_points_cm) - ob.known_cm;
      const double sigmas = std::sqrt(std::max(0.0, error.dot(c.ldlt().solve(error))));
      if (sigmas > worst_sigmas) {
        worst = p;
        worst_sigmas = sigmas;
        worst_error = error;
      }
    }
    if (!(worst_sigmas > settings.blunder_sigmas)) break;
    used[worst] = false;
    ControlResidual& r = residuals[worst];
    r.blunder = true;
    r.residual_m = axes.transpose() * worst_error / 100.0;
    r.sigmas = worst_sigmas;
    adjusted = adjust(used, adjusted, level_of(used, adjusted));
  }

  // The closure: where the map as matched, moved rigidly onto the points kept, put each point,
  // before the tie bent it.
  const Pose closing = helmert_of(used).value_or(*helmert);
  std::set<std::size_t> closed_points;
  for (const Observed& ob : observed) {
    if (!closed_points.insert(ob.point).second) continue;
    const Eigen::Vector3d before = placed(closing * poses[ob.scan], ob.in_points_cm) - ob.known_cm;
    residuals[ob.point].before_m = axes.transpose() * before / 100.0;
  }

  // The residuals of the points kept, in their own sigmas, and each scan's covariance.
  ControlTie tie;
  tie.file = control.path;
  tie.epsg = control.epsg;
  tie.origin_cm = origin;
  tie.checked_for_blunders = points_observed.size() >= 4;
  double sum_squares = 0.0;
  for (const std::size_t p : points_observed) {
    if (!used[p]) continue;
    const Observed& ob = first_observation(p);
    const Eigen::Vector3d error = placed(adjusted[ob.scan], ob.in_points_cm) - ob.known_cm;
    ControlResidual& r = residuals[p];
    r.residual_m = axes.transpose() * error / 100.0;
    r.sigmas = std::sqrt(std::max(0.0, error.dot(ob.covariance.ldlt().solve(error))));
    sum_squares += r.residual_m.squaredNorm();
    ++tie.points_used;
  }
  tie.rms_m = tie.points_used > 0 ? std::sqrt(sum_squares / tie.points_used) : 0.0;
  {
    std::size_t first = n, last = 0;
    for (const Observed& ob : observed) {
      first = std::min(first, ob.scan);
      last = std::max(last, ob.scan);
    }
    for (std::size_t k = first + 1; k <= last && k < n; ++k) {
      tie.drive_cm += (poses[k].block<3, 1>(0, 3) - poses[k - 1].block<3, 1>(0, 3)).norm();
    }
    double largest_m = 0.0;
    for (const std::size_t p : points_observed) {
      if (used[p]) largest_m = std::max(largest_m, residuals[p].before_m.norm());
    }
    tie.closure_ppm = tie.drive_cm > 0.0 ? 1e6 * 100.0 * largest_m / tie.drive_cm : 0.0;
  }
  for (const std::size_t p : points_observed) tie.residuals.push_back(residuals[p]);
  std::vector<std::size_t> all(n);
  for (std::size_t k = 0; k < n; ++k) all[k] = k;
  const std::vector<Matrix6d> covariances =
      pose_graph_covariances(adjusted, result.graph, priors_of(used), level_of(used, adjusted), kNoFixedPose,
                             graph_settings, all);
  double bent_sum = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const double bent = (adjusted[k].block<3, 1>(0, 3) - rigid[k].block<3, 1>(0, 3)).norm();
    tie.bent_max_cm = std::max(tie.bent_max_cm, bent);
    bent_sum += bent;
  }
  tie.bent_mean_cm = n > 0 ? bent_sum / static_cast<double>(n) : 0.0;

  // The one place a tie moves the scans: every pose it took into the grid, the final one adjusted.
  for (std::size_t k = 0; k < n; ++k) {
    ScanOutcome& scan = result.scans[k];
    const Pose points_from_file = rigid_inverse(scan.world_from_points) * scan.pose_cm;
    for (io::FrameLine& frame : scan.frames) frame.pose_cm = orthonormalised(*helmert * frame.pose_cm);
    scan.world_from_points = adjusted[k];
    scan.pose_cm = adjusted[k] * points_from_file;
    scan.frames.push_back({scan.pose_cm, 1});
    scan.covariance = scale2 * covariances[k];
  }
  // A blunder, or a point that the tie cannot meet, makes the scans observing it doubtful.
  for (const ControlResidual& r : tie.residuals) {
    if (!r.blunder && !(r.sigmas > settings.blunder_sigmas)) continue;
    char text[400];
    if (r.blunder) {
      std::snprintf(text, sizeof text,
                    "control point %s lies %.1f cm from where the map tied to the other points puts it (%.1f sigmas; "
                    "E %+.1f N %+.1f H %+.1f cm): a blunder in %s or the wrong mark? Left out of the tie",
                    r.point.c_str(), 100.0 * r.residual_m.norm(), r.sigmas, 100.0 * r.residual_m.x(),
                    100.0 * r.residual_m.y(), 100.0 * r.residual_m.z(), control.path.c_str());
    } else {
      std::snprintf(text, sizeof text,
                    "control point %s is %.1f cm from the tied map (%.1f of its sigmas): the control and the map "
                    "disagree there; check the point, or give more control",
                    r.point.c_str(), 100.0 * r.residual_m.norm(), r.sigmas);
    }
    for (const std::size_t k : r.scans) {
      RegistrationHealth& health = result.scans[k].health;
      health.judged = true;
      health.doubt = health.doubt.empty() ? std::string(text) : health.doubt + "; " + text;
    }
  }
  result.control = std::move(tie);
}

}  // namespace minemap
