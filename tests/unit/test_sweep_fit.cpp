// One sweep fitted as it was measured (registration/sweep_fit.hpp): its pose at the middle and its
// motion over the sweep, against a model that is right.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/registration/sweep_fit.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

constexpr double kRadPerDeg = M_PI / 180.0;

/// An axis-aligned box's faces [lo, hi], points `spacing_cm` apart on a grid, or `count` random
/// points on them (seeded) where count > 0.
void add_box(std::vector<Eigen::Vector3d>& out, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
             double spacing_cm, std::mt19937* random = nullptr, int count = 0) {
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (const double side : {lo(axis), hi(axis)}) {
      if (random != nullptr) {
        std::uniform_real_distribution<double> a(lo(u), hi(u)), b(lo(v), hi(v));
        for (int k = 0; k < count; ++k) {
          Eigen::Vector3d p;
          p(axis) = side, p(u) = a(*random), p(v) = b(*random);
          out.push_back(p);
        }
        continue;
      }
      for (double a = lo(u); a <= hi(u); a += spacing_cm) {
        for (double b = lo(v); b <= hi(v); b += spacing_cm) {
          Eigen::Vector3d p;
          p(axis) = side, p(u) = a, p(v) = b;
          out.push_back(p);
        }
      }
    }
  }
}

/// A chamber 12 x 8 x 4 m with two pillars of different sizes: every turn and shift is pinned.
struct Chamber {
  std::vector<Eigen::Vector3d> boxes_lo{{-600, -400, -150}, {200, 100, -150}, {-380, -260, -150}};
  std::vector<Eigen::Vector3d> boxes_hi{{600, 400, 250}, {280, 220, 250}, {-230, -200, 250}};

  std::vector<Eigen::Vector3d> grid(double spacing_cm) const {
    std::vector<Eigen::Vector3d> out;
    for (std::size_t b = 0; b < boxes_lo.size(); ++b) add_box(out, boxes_lo[b], boxes_hi[b], spacing_cm);
    return out;
  }
  std::vector<Eigen::Vector3d> random(int per_face, std::uint32_t seed) const {
    std::mt19937 random(seed);
    std::vector<Eigen::Vector3d> out;
    for (std::size_t b = 0; b < boxes_lo.size(); ++b) add_box(out, boxes_lo[b], boxes_hi[b], 0.0, &random, per_face);
    return out;
  }
};

/// A spinning sensor's sweep of the chamber: each point taken at the fraction of the sweep its
/// azimuth about the sensor gives, from the pose the sensor then had, world_from_middle *
/// exp(f log motion) (the model fit_sweep fits), and written in the sensor's frame at that instant.
struct Sweep {
  std::vector<Eigen::Vector3d> points_cm;
  std::vector<float> fractions;
};
Sweep sweep_of(const std::vector<Eigen::Vector3d>& world, const Pose& world_from_middle, const Pose& motion) {
  Sweep sweep;
  const Twist twist = se3_log(motion);
  const Eigen::Vector3d centre = world_from_middle.block<3, 1>(0, 3);
  for (const Eigen::Vector3d& x : world) {
    const double f = std::atan2(x.y() - centre.y(), x.x() - centre.x()) / (2.0 * M_PI);
    const Pose sensor = world_from_middle * se3_exp(f * twist);
    sweep.points_cm.push_back((rigid_inverse(sensor) * x.homogeneous()).head<3>());
    sweep.fractions.push_back(static_cast<float>(f));
  }
  return sweep;
}

Pose pose_of(double yaw_deg, double roll_deg, const Eigen::Vector3d& t) {
  Pose pose = Pose::Identity();
  pose.block<3, 3>(0, 0) = (Eigen::AngleAxisd(yaw_deg * kRadPerDeg, Eigen::Vector3d::UnitZ()) *
                            Eigen::AngleAxisd(roll_deg * kRadPerDeg, Eigen::Vector3d::UnitX()))
                               .toRotationMatrix();
  pose.block<3, 1>(0, 3) = t;
  return pose;
}

struct Model {
  std::shared_ptr<const PreparedCloud> cloud;
  SurfaceNormals normals;
};
Model model_on(ComputeBackend& backend, const std::vector<Eigen::Vector3d>& points) {
  std::vector<Eigen::Vector3f> cloud;
  for (const Eigen::Vector3d& p : points) cloud.push_back(p.cast<float>());
  SurfaceNormals normals(cloud, 50.0f);
  return {backend.prepare(std::move(cloud), KdTreeSettings{}), std::move(normals)};
}

// The chamber's sweep that turned 30 deg and moved 80 cm while it was taken, with the model in a
// frame of its own (world_from_model, as the later sweeps' union is), and the start the step after
// it would give (a third of the turn, the middle 3 deg and 13 cm off).
struct TurnedSweep {
  Chamber chamber;
  Pose world_from_model = pose_of(-20.0, 1.0, {3000.0, -1200.0, 40.0});
  std::vector<Eigen::Vector3d> model_points = in_model_frame(chamber.grid(8.0), world_from_model);
  Pose middle = pose_of(10.0, 2.0, {50.0, -30.0, 20.0});
  Pose motion = se3_exp((Twist() << 0.02, -0.01, 30.0 * kRadPerDeg, 80.0, 10.0, -3.0).finished());
  Sweep sweep = sweep_of(chamber.random(1500, 7), middle, motion);
  Pose start = middle * pose_of(3.0, -0.5, {10.0, -8.0, 3.0});
  Pose start_motion = se3_exp(0.35 * se3_log(motion));

  static std::vector<Eigen::Vector3d> in_model_frame(const std::vector<Eigen::Vector3d>& world, const Pose& world_from_model) {
    std::vector<Eigen::Vector3d> model;
    for (const Eigen::Vector3d& p : world) model.push_back((rigid_inverse(world_from_model) * p.homogeneous()).head<3>());
    return model;
  }
};

// A sweep that turned 30 deg and moved 80 cm while it was taken, started where the step after it
// would put it (a third of the turn, the middle 3 deg and 13 cm off): the fit finds the middle's
// pose and the motion. The model sits in a frame of its own (world_from_model), as the later
// sweeps' union does. The same fit on the OpenCL backend gives the same bits.
TEST(SweepFit, FindsTheMiddlesPoseAndTheMotionOverASweepThatTurned30Deg) {
  const TurnedSweep turned;
  const Pose& world_from_model = turned.world_from_model;
  const std::vector<Eigen::Vector3d>& model_points = turned.model_points;
  const Pose &middle = turned.middle, &motion = turned.motion, &start = turned.start, &start_motion = turned.start_motion;
  const Sweep& sweep = turned.sweep;

  auto cpu = make_cpu_backend();
  const Model model = model_on(*cpu, model_points);
  const SweepFit fit = fit_sweep(*cpu, sweep.points_cm, sweep.fractions, WorldModel{model.cloud.get(), world_from_model},
                                 model.normals, start, start_motion, SweepFitSettings{});
  const Pose middle_off = rigid_inverse(middle) * fit.world_from_sweep;
  const Pose motion_off = rigid_inverse(motion) * fit.motion;
  std::printf("%d iterations, %zu pairs, rms %.3f cm; middle off %.3f cm %.4f deg, motion off %.3f cm %.4f deg "
              "(started %.1f deg short)\n",
              fit.iterations, fit.pairs, fit.rms_cm, translation_norm(middle_off), rotation_angle_deg(middle_off),
              translation_norm(motion_off), rotation_angle_deg(motion_off),
              rotation_angle_deg(motion) - rotation_angle_deg(start_motion));
  EXPECT_TRUE(fit.converged);
  EXPECT_LE(fit.iterations, 30);  // Gauss-Newton on exact derivatives: a few per stage
  EXPECT_GT(fit.pairs, 10000u);
  EXPECT_LT(fit.rms_cm, 1.0);  // pairs across a corner's edge
  EXPECT_LT(translation_norm(middle_off), 0.5);
  EXPECT_LT(rotation_angle_deg(middle_off), 0.05);
  EXPECT_LT(translation_norm(motion_off), 1.0);
  EXPECT_LT(rotation_angle_deg(motion_off), 0.1);

  // The case for the stages: all of the sweep at once from that start pairs the ends, 10 deg off,
  // with the wrong walls, and the fit converges elsewhere.
  SweepFitSettings one_stage;
  one_stage.stages = 1;
  const SweepFit at_once = fit_sweep(*cpu, sweep.points_cm, sweep.fractions, WorldModel{model.cloud.get(), world_from_model},
                                     model.normals, start, start_motion, one_stage);
  const double at_once_off_deg = rotation_angle_deg(rigid_inverse(middle) * at_once.world_from_sweep);
  std::printf("one stage from the same start: middle off %.3f deg\n", at_once_off_deg);
  EXPECT_GT(at_once_off_deg, 10.0 * rotation_angle_deg(middle_off));

  // A sweep whose middle sees nothing of the model (the sensor's own vehicle there): the first
  // stage has no pairs and leaves the fit where it is; the later stages fit it.
  Sweep blind;
  for (std::size_t i = 0; i < sweep.points_cm.size(); ++i) {
    if (std::abs(sweep.fractions[i]) < 0.13f) continue;
    blind.points_cm.push_back(sweep.points_cm[i]);
    blind.fractions.push_back(sweep.fractions[i]);
  }
  const SweepFit around = fit_sweep(*cpu, blind.points_cm, blind.fractions, WorldModel{model.cloud.get(), world_from_model},
                                    model.normals, start, start_motion, SweepFitSettings{});
  const Pose around_off = rigid_inverse(middle) * around.world_from_sweep;
  std::printf("the middle unseen: middle off %.3f cm %.4f deg\n", translation_norm(around_off), rotation_angle_deg(around_off));
  EXPECT_TRUE(around.converged);
  EXPECT_LT(rotation_angle_deg(around_off), 0.05);
  EXPECT_LT(translation_norm(around_off), 0.5);

  auto device = test::opencl_backend();  // throws (the test fails) without OpenCL
  ASSERT_NE(device, nullptr);
  const Model on_device = model_on(*device, model_points);
  const SweepFit same = fit_sweep(*device, sweep.points_cm, sweep.fractions,
                                  WorldModel{on_device.cloud.get(), world_from_model}, on_device.normals, start,
                                  start_motion, SweepFitSettings{});
  EXPECT_EQ(same.world_from_sweep, fit.world_from_sweep);
  EXPECT_EQ(same.motion, fit.motion);
  EXPECT_EQ(same.iterations, fit.iterations);
}

// A fit whose pairs change by a few each iteration wanders about where it has settled and may never
// step under the least steps: at its last stage's cap it has converged where its last iterations
// all moved less than the settled steps (SweepFitSettings::settle_iterations). Least steps of 0 stand
// for such churn here: no stage converges, the last settles, as close as the converged fit.
TEST(SweepFit, AFitThatOnlyWandersAtItsLastStagesCapHasSettled) {
  const TurnedSweep turned;
  const Pose& world_from_model = turned.world_from_model;
  const std::vector<Eigen::Vector3d>& model_points = turned.model_points;
  const Pose &middle = turned.middle, &motion = turned.motion, &start = turned.start, &start_motion = turned.start_motion;
  const Sweep& sweep = turned.sweep;
  auto cpu = make_cpu_backend();
  const Model model = model_on(*cpu, model_points);
  const auto run = [&](const SweepFitSettings& settings) {
    return fit_sweep(*cpu, sweep.points_cm, sweep.fractions, WorldModel{model.cloud.get(), world_from_model},
                     model.normals, start, start_motion, settings);
  };
  SweepFitSettings never;
  never.min_translation_step_cm = 0.0;
  never.min_rotation_step_deg = 0.0;
  never.max_iterations = 12;
  const SweepFit settled = run(never);
  const Pose middle_off = rigid_inverse(middle) * settled.world_from_sweep;
  const Pose motion_off = rigid_inverse(motion) * settled.motion;
  std::printf("settled after %d iterations: middle off %.3f cm %.4f deg, motion off %.3f cm %.4f deg\n",
              settled.iterations, translation_norm(middle_off), rotation_angle_deg(middle_off),
              translation_norm(motion_off), rotation_angle_deg(motion_off));
  EXPECT_TRUE(settled.converged);
  EXPECT_TRUE(settled.settled);
  EXPECT_EQ(settled.iterations, 4 * never.max_iterations);
  EXPECT_LT(translation_norm(middle_off), 0.5);
  EXPECT_LT(rotation_angle_deg(middle_off), 0.05);
  EXPECT_LT(rotation_angle_deg(motion_off), 0.1);
  const SweepFit converged = run(SweepFitSettings{});  // converges to the least steps: not "settled"
  EXPECT_TRUE(converged.converged);
  EXPECT_FALSE(converged.settled);

  SweepFitSettings off = never;
  off.settle_iterations = 0;
  const SweepFit unsettled = run(off);
  EXPECT_FALSE(unsettled.converged);
  EXPECT_FALSE(unsettled.settled);
  EXPECT_EQ(unsettled.world_from_sweep, settled.world_from_sweep);  // the same fit, judged otherwise
  SweepFitSettings tight = never;
  tight.settled_step_cm = 1e-9;
  EXPECT_FALSE(run(tight).converged);
  SweepFitSettings longer = never;
  longer.settle_iterations = never.max_iterations + 1;  // more than the stage ran
  EXPECT_FALSE(run(longer).converged);
  SweepFitSettings bad;
  bad.settle_iterations = -1;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad = SweepFitSettings{};
  bad.settled_step_deg = -0.1;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

// A sweep with no model around it fails the fit (too few pairs), and says so; bad settings and
// inputs are refused.
TEST(SweepFit, ASweepOutOfTheModelsReachFailsAndBadSettingsAreRefused) {
  const Chamber chamber;
  auto cpu = make_cpu_backend();
  const Model model = model_on(*cpu, chamber.grid(10.0));
  const Pose middle = pose_of(0.0, 0.0, {0.0, 0.0, 0.0});
  const Sweep sweep = sweep_of(chamber.random(300, 3), middle, Pose::Identity());
  const Pose far_away = pose_of(0.0, 0.0, {5000.0, 0.0, 0.0});
  const SweepFit fit = fit_sweep(*cpu, sweep.points_cm, sweep.fractions, WorldModel{model.cloud.get(), Pose::Identity()},
                                 model.normals, far_away, Pose::Identity(), SweepFitSettings{});
  EXPECT_FALSE(fit.converged);
  EXPECT_LT(fit.pairs, static_cast<std::size_t>(SweepFitSettings{}.min_pairs));
  EXPECT_EQ(fit.world_from_sweep, far_away);
  EXPECT_EQ(fit.motion, Pose::Identity());  // the start motion, as it was

  const auto refused = [&](SweepFitSettings settings) {
    EXPECT_THROW(fit_sweep(*cpu, sweep.points_cm, sweep.fractions, WorldModel{model.cloud.get(), Pose::Identity()},
                           model.normals, middle, Pose::Identity(), settings),
                 std::invalid_argument);
  };
  SweepFitSettings bad;
  bad.stages = 0;
  refused(bad);
  bad = {};
  bad.max_pair_dist_cm = 0.0f;
  refused(bad);
  bad = {};
  bad.max_iterations = 0;
  refused(bad);
  bad = {};
  bad.min_pairs = 5;
  refused(bad);
  const std::vector<float> short_fractions(sweep.fractions.begin(), sweep.fractions.end() - 1);
  EXPECT_THROW(fit_sweep(*cpu, sweep.points_cm, short_fractions, WorldModel{model.cloud.get(), Pose::Identity()},
                         model.normals, middle, Pose::Identity(), SweepFitSettings{}),
               std::invalid_argument);
}

}  // namespace
}  // namespace minemap
