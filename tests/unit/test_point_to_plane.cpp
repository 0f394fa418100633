// Point-to-plane ICP (search/plane_sums.hpp, registration/point_to_plane.hpp): the sums against
// the objective's derivatives taken by finite differences from its definition, the step against
// known motions, and the sums' bits on both backends and any thread count.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <Eigen/Geometry>
#include <bit>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/registration/match_information.hpp"
#include "minemap/registration/point_to_plane.hpp"
#include "minemap/search/plane_sums.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

using Vector6d = Eigen::Matrix<double, 6, 1>;

Eigen::Vector3d apply(const Pose& t, const Eigen::Vector3d& p) { return t.block<3, 3>(0, 0) * p + t.block<3, 1>(0, 3); }

/// The model's small motion U(x) about `reference` from its definition: rotation exp(w) about the
/// reference, then translation t (x = [w, t]).
Eigen::Vector3d moved_by(const Vector6d& x, const Eigen::Vector3d& reference, const Eigen::Vector3d& m) {
  const Eigen::Vector3d w = x.head<3>();
  const double angle = w.norm();
  const Eigen::Matrix3d rotation =
      angle > 0.0 ? Eigen::AngleAxisd(angle, w / angle).toRotationMatrix() : Eigen::Matrix3d::Identity();
  return rotation * (m - reference) + reference + x.tail<3>();
}

/// The residuals of one pair under U(x), from the objective's definition: the distance of U m from
/// the data point's plane, or the three coordinates of U m - p where the point has no plane.
std::vector<double> residuals(const Vector6d& x, const Eigen::Vector3d& reference, const Eigen::Vector3d& p,
                              const Eigen::Vector3d& m, const Eigen::Vector3d& n) {
  const Eigen::Vector3d difference = moved_by(x, reference, m) - p;
  if (n.squaredNorm() > 0.0) return {difference.dot(n)};
  return {difference.x(), difference.y(), difference.z()};
}

struct RandomPairs {
  std::vector<Eigen::Vector3f> data, normals;
  std::vector<NearestPair> pairs;
};

/// Pairs around a point far from the origin, two in three on a plane, one in five unpaired.
RandomPairs random_pairs(std::size_t count, std::uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> spread(-800.0f, 800.0f), offset(-20.0f, 20.0f);
  std::normal_distribution<float> direction(0.0f, 1.0f);
  RandomPairs out;
  const Eigen::Vector3f far(2.0e5f, -3.0e4f, 900.0f);
  for (std::size_t i = 0; i < count; ++i) {
    const Eigen::Vector3f p = far + Eigen::Vector3f(spread(random), spread(random), spread(random));
    const Eigen::Vector3f m = p + Eigen::Vector3f(offset(random), offset(random), offset(random));
    out.data.push_back(p);
    out.normals.push_back(i % 3 == 2 ? Eigen::Vector3f::Zero()
                                     : Eigen::Vector3f(direction(random), direction(random), direction(random)).normalized());
    NearestPair pair;
    if (i % 5 != 4) pair = {(m - p).squaredNorm(), 0, static_cast<std::int32_t>(i), m};
    out.pairs.push_back(pair);
  }
  return out;
}

// The sums are J^T J and J^T r of the objective's residuals: J taken here by central differences
// of the residuals written from the definition (moved_by), not from the rows the sums write.
TEST(PlaneSums, AreTheGaussNewtonSumsOfTheObjectivesResiduals) {
  const RandomPairs input = random_pairs(500, 3);
  const Eigen::Vector3d reference(2.0e5 + 10.0, -3.0e4 - 20.0, 930.0);
  const PlaneSums sums = plane_sums(input.pairs, input.data, input.normals, reference);
  Eigen::Matrix<double, 6, 6> normal = Eigen::Matrix<double, 6, 6>::Zero();
  Vector6d gradient = Vector6d::Zero();
  double objective = 0.0, squared_distance = 0.0;
  std::size_t count = 0, on_planes = 0;
  for (std::size_t i = 0; i < input.pairs.size(); ++i) {
    if (input.pairs[i].squared_distance_cm2 < 0.0f) continue;
    const Eigen::Vector3d p = input.data[i].cast<double>(), m = input.pairs[i].position_cm.cast<double>();
    const Eigen::Vector3d n = input.normals[i].cast<double>();
    const std::vector<double> r0 = residuals(Vector6d::Zero(), reference, p, m, n);
    Eigen::MatrixXd jacobian(r0.size(), 6);
    for (int k = 0; k < 6; ++k) {
      const double h = 1e-6;
      Vector6d plus = Vector6d::Zero(), minus = Vector6d::Zero();
      plus[k] = h;
      minus[k] = -h;
      const std::vector<double> a = residuals(plus, reference, p, m, n), b = residuals(minus, reference, p, m, n);
      for (std::size_t r = 0; r < r0.size(); ++r) jacobian(static_cast<Eigen::Index>(r), k) = (a[r] - b[r]) / (2 * h);
    }
    const Eigen::VectorXd r = Eigen::Map<const Eigen::VectorXd>(r0.data(), static_cast<Eigen::Index>(r0.size()));
    normal += jacobian.transpose() * jacobian;
    gradient += jacobian.transpose() * r;
    objective += r.squaredNorm();
    squared_distance += (m - p).squaredNorm();
    ++count;
    on_planes += n.squaredNorm() > 0.0 ? 1 : 0;
  }
  EXPECT_EQ(sums.count, static_cast<double>(count));
  EXPECT_EQ(sums.plane_pairs, static_cast<double>(on_planes));
  EXPECT_NEAR(sums.sum_squared_residual_cm2, objective, 1e-9 * objective);
  EXPECT_NEAR(sums.sum_squared_distance_cm2, squared_distance, 1e-6 * squared_distance);
  const Eigen::Matrix<double, 6, 6> written = sums.normal_matrix();
  EXPECT_TRUE(written.isApprox(written.transpose(), 0.0));
  EXPECT_LT((written - normal).norm(), 1e-6 * normal.norm()) << "J^T J\n" << written << "\nagainst\n" << normal;
  EXPECT_LT((sums.gradient_vector() - gradient).norm(), 1e-6 * gradient.norm());
}

/// Points on the six faces of a box (unit normals), far from the origin.
RandomPairs box_faces(std::size_t count, std::uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> along(-400.0f, 400.0f);
  RandomPairs out;
  const Eigen::Vector3f centre(5.0e3f, 2.0e3f, -700.0f);
  for (std::size_t i = 0; i < count; ++i) {
    const int axis = static_cast<int>(i % 3);
    const float side = (i / 3) % 2 == 0 ? -400.0f : 400.0f;
    Eigen::Vector3f p(along(random), along(random), along(random));
    p[axis] = side;
    Eigen::Vector3f n = Eigen::Vector3f::Zero();
    n[axis] = side > 0.0f ? 1.0f : -1.0f;
    out.data.push_back(centre + p);
    out.normals.push_back(n);
  }
  return out;
}

/// The pairs of `data` with its own points moved by `model_from_data` (each point's twin, in the
/// data frame of `pose`: where the data sits after the steps so far).
std::vector<NearestPair> twins(const RandomPairs& box, const Pose& model_from_data, const Pose& pose) {
  std::vector<NearestPair> pairs;
  const Pose in_data = rigid_inverse(pose) * model_from_data;
  for (std::size_t i = 0; i < box.data.size(); ++i) {
    const Eigen::Vector3f m = apply(in_data, box.data[i].cast<double>()).cast<float>();
    pairs.push_back({(m - box.data[i]).squaredNorm(), 0, static_cast<std::int32_t>(i), m});
  }
  return pairs;
}

// A translation is linear in the objective: one step lands on it. A motion with a turn lands in a
// few steps (Gauss-Newton on exact pairs).
TEST(PlaneStep, ReachesAKnownMotionOfABoxsFaces) {
  const RandomPairs box = box_faces(3000, 5);
  const Eigen::Vector3d reference = Eigen::Vector3d(5.0e3, 2.0e3, -700.0);
  Pose shift = Pose::Identity();
  shift.block<3, 1>(0, 3) = Eigen::Vector3d(6.0, -4.0, 9.0);
  const auto step = plane_step(plane_sums(twins(box, shift, Pose::Identity()), box.data, box.normals, reference));
  ASSERT_TRUE(step.has_value());
  std::printf("one step for a shift: off by %.2e cm\n", (*step - shift).norm());
  EXPECT_LT((*step - shift).norm(), 1e-4) << *step;

  Pose turn = Pose::Identity();
  turn.block<3, 3>(0, 0) = Eigen::AngleAxisd(2.0 * M_PI / 180.0, Eigen::Vector3d(0.3, 1.0, -0.2).normalized()).toRotationMatrix();
  turn.block<3, 1>(0, 3) = reference - turn.block<3, 3>(0, 0) * reference + Eigen::Vector3d(-12.0, 5.0, 3.0);
  Pose pose = Pose::Identity();
  for (int steps = 1; steps <= 4; ++steps) {
    const auto next = plane_step(plane_sums(twins(box, turn, pose), box.data, box.normals, reference));
    ASSERT_TRUE(next.has_value());
    pose = pose * *next;
    std::printf("turn: after %d steps off by %.2e cm, %.2e deg\n", steps, translation_norm(rigid_inverse(turn) * pose),
                rotation_angle_deg(rigid_inverse(turn) * pose));
  }
  EXPECT_LT(translation_norm(rigid_inverse(turn) * pose), 1e-3);
  EXPECT_LT(rotation_angle_deg(rigid_inverse(turn) * pose), 1e-5);
  EXPECT_TRUE(is_valid_rigid(pose, 1e-9));
}

// A direction no pair measures gets no motion: points on one plane slid along it stay where they are
// along it, and the step corrects only the distance to the plane.
TEST(PlaneStep, LeavesWhatNoPairMeasuresWhereItIs) {
  RandomPairs floor = box_faces(3000, 7);
  RandomPairs one_plane;
  for (std::size_t i = 0; i < floor.data.size(); ++i) {
    if (floor.normals[i].z() > 0.5f) {
      one_plane.data.push_back(floor.data[i]);
      one_plane.normals.push_back(floor.normals[i]);
    }
  }
  Pose slid = Pose::Identity();
  slid.block<3, 1>(0, 3) = Eigen::Vector3d(30.0, -20.0, 4.0);  // 36 cm along the plane, 4 cm off it
  const auto step = plane_step(plane_sums(twins(one_plane, slid, Pose::Identity()), one_plane.data, one_plane.normals,
                                          Eigen::Vector3d(5.0e3, 2.0e3, -300.0)));
  ASSERT_TRUE(step.has_value());
  EXPECT_NEAR((*step)(2, 3), 4.0, 1e-4);
  EXPECT_LT(std::hypot((*step)(0, 3), (*step)(1, 3)), 1e-3);
  EXPECT_LT(rotation_angle_deg(*step), 1e-6);
}

TEST(PlaneStep, RefusesTooFewPairsAndNonFiniteSums) {
  const RandomPairs box = box_faces(60, 9);
  const Eigen::Vector3d reference(5.0e3, 2.0e3, -700.0);
  PlaneSums sums = plane_sums(twins(box, Pose::Identity(), Pose::Identity()), box.data, box.normals, reference);
  EXPECT_TRUE(plane_step(sums).has_value());
  PlaneSums few = sums;
  few.count = 5.0;
  EXPECT_FALSE(plane_step(few).has_value());
  PlaneSums broken = sums;
  broken.gradient[2] = std::nan("");
  EXPECT_FALSE(plane_step(broken).has_value());
  EXPECT_THROW(plane_sums(twins(box, Pose::Identity(), Pose::Identity()), box.data, {}, reference),
               std::invalid_argument);
}

/// A backend that keeps ComputeBackend's own pair_and_plane_sum (nearest(), then plane_sums),
/// as the OpenCL backend does.
class HostPlaneSums final : public ComputeBackend {
 public:
  explicit HostPlaneSums(std::unique_ptr<ComputeBackend> inner) : inner_(std::move(inner)) {}
  std::string name() const override { return inner_->name(); }
  std::string device_description() const override { return inner_->device_description(); }
  std::shared_ptr<const PreparedCloud> prepare(std::vector<Eigen::Vector3f> points, const KdTreeSettings& tree,
                                               TreeBuild when) override {
    return inner_->prepare(std::move(points), tree, when);
  }
  PairSums pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                        const PairingSettings& settings) override {
    return inner_->pair_and_sum(data, models, method, settings);
  }
  std::vector<NearestPair> nearest(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                   SearchMethod method, const PairingSettings& settings) override {
    return inner_->nearest(data, models, method, settings);
  }

 protected:
  SliceFilterResult filter_slices_checked(const Scan& scan, const SliceFilterSettings& settings) override {
    return inner_->filter_slices(scan, settings);
  }

 private:
  std::unique_ptr<ComputeBackend> inner_;
};

bool same_bits(const PlaneSums& a, const PlaneSums& b) {
  for (int k = 0; k < 21; ++k) {
    if (std::bit_cast<std::uint64_t>(a.normal[k]) != std::bit_cast<std::uint64_t>(b.normal[k])) return false;
  }
  for (int k = 0; k < 6; ++k) {
    if (std::bit_cast<std::uint64_t>(a.gradient[k]) != std::bit_cast<std::uint64_t>(b.gradient[k])) return false;
  }
  return a.count == b.count && a.plane_pairs == b.plane_pairs &&
         std::bit_cast<std::uint64_t>(a.sum_squared_residual_cm2) ==
             std::bit_cast<std::uint64_t>(b.sum_squared_residual_cm2) &&
         std::bit_cast<std::uint64_t>(a.sum_squared_distance_cm2) ==
             std::bit_cast<std::uint64_t>(b.sum_squared_distance_cm2);
}

// The CPU backend sums while it searches; the default (and so the OpenCL backend) pairs first and
// sums on the host: the same bits, for one thread or two, and on the device.
TEST(PlaneSums, EveryBackendAndThreadCountGivesTheSameBits) {
  const auto model_points = test::random_cloud(20000, -500.f, 500.f, 21);
  const auto data_points = test::random_cloud(3000, -480.f, 480.f, 22);
  std::vector<Eigen::Vector3f> normals;
  for (std::size_t i = 0; i < data_points.size(); ++i) {
    normals.push_back(i % 4 == 3 ? Eigen::Vector3f::Zero() : Eigen::Vector3f(0.6f, 0.0f, 0.8f));
  }
  Pose placement = Pose::Identity();
  placement.block<3, 3>(0, 0) = Eigen::AngleAxisd(0.1, Eigen::Vector3d(0, 0, 1)).toRotationMatrix();
  placement.block<3, 1>(0, 3) = Eigen::Vector3d(3.0, -2.0, 1.0);
  const auto sums_on = [&](ComputeBackend& backend, SearchMethod method) {
    const auto model = backend.prepare(model_points, {});
    const auto data = backend.prepare(data_points, {});
    const ModelPlacement placed{model.get(), placement};
    return backend.pair_and_plane_sum(*data, {&placed, 1}, method, PairingSettings{60.0f}, normals);
  };
  for (const SearchMethod method : {SearchMethod::kExact, SearchMethod::kApproximate, SearchMethod::kBruteForce}) {
    auto cpu = make_cpu_backend();
    const PlaneSums fused = sums_on(*cpu, method);
    std::printf("%s: %.0f pairs, %.0f on planes\n", to_string(method), fused.count, fused.plane_pairs);
    EXPECT_GT(fused.count, method == SearchMethod::kApproximate ? 300.0 : 1500.0) << to_string(method);
    EXPECT_GT(fused.plane_pairs, 0.5 * fused.count) << to_string(method);
    HostPlaneSums host(make_cpu_backend());
    EXPECT_TRUE(same_bits(fused, sums_on(host, method))) << to_string(method);
    tbb::task_arena one(1);
    PlaneSums alone;
    one.execute([&] { alone = sums_on(*cpu, method); });
    EXPECT_TRUE(same_bits(fused, alone)) << to_string(method);
    auto device = test::opencl_backend();  // throws (the test fails) without OpenCL
    ASSERT_NE(device, nullptr);
    EXPECT_TRUE(same_bits(fused, sums_on(*device, method))) << to_string(method);
  }
}

}  // namespace
}  // namespace minemap
