// Point-to-plane information of a match (registration/match_information.hpp): planes found where
// there are planes and nowhere else; a box's corner pins every direction; a smooth tunnel leaves
// the slide along it free, and the relaxation then puts a loop's gap there.
#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "minemap/registration/match_information.hpp"
#include "minemap/slam/pose_graph.hpp"

namespace minemap {
namespace {

/// Points on the plane through `origin` spanned by u and v, on a 5 cm grid, `size_cm` square.
void add_plane(std::vector<Eigen::Vector3f>& points, const Eigen::Vector3f& origin, const Eigen::Vector3f& u,
               const Eigen::Vector3f& v, float size_cm) {
  for (float a = 0.0f; a < size_cm; a += 5.0f) {
    for (float b = 0.0f; b < size_cm; b += 5.0f) points.push_back(origin + a * u + b * v);
  }
}

/// A tunnel along z, 400 cm wide and 250 cm high, 2000 cm long: two ribs, a floor and a roof.
std::vector<Eigen::Vector3f> tunnel() {
  std::vector<Eigen::Vector3f> points;
  const Eigen::Vector3f x = Eigen::Vector3f::UnitX(), y = Eigen::Vector3f::UnitY(), z = Eigen::Vector3f::UnitZ();
  for (float along = -1000.0f; along < 1000.0f; along += 250.0f) {
    add_plane(points, {-200.0f, -125.0f, along}, y, z, 250.0f);  // left rib
    add_plane(points, {200.0f, -125.0f, along}, y, z, 250.0f);   // right rib
    for (float across = -200.0f; across < 200.0f; across += 200.0f) {
      add_plane(points, {across, -125.0f, along}, x, z, 200.0f);  // floor
      add_plane(points, {across, 125.0f, along}, x, z, 200.0f);   // roof
    }
  }
  return points;
}

TEST(SurfaceNormals, PlanesHaveTheirNormalAndScatterHasNone) {
  std::vector<Eigen::Vector3f> floor;
  add_plane(floor, {0.3f, 20.0f, 0.7f}, Eigen::Vector3f::UnitX(), Eigen::Vector3f::UnitZ(), 200.0f);
  const SurfaceNormals on_floor(floor, 50.0f);
  ASSERT_GT(on_floor.planes(), 0u);
  const Eigen::Vector3f* n = on_floor.at({100.0f, 20.0f, 100.0f});
  ASSERT_NE(n, nullptr);
  EXPECT_NEAR(std::abs(n->y()), 1.0f, 1e-4f);
  EXPECT_EQ(on_floor.at({100.0f, 500.0f, 100.0f}), nullptr);  // no point there

  std::mt19937 random(7);
  std::uniform_real_distribution<float> uniform(0.0f, 50.0f);
  std::vector<Eigen::Vector3f> scatter(2000);
  for (auto& p : scatter) p = {uniform(random), uniform(random), uniform(random)};
  EXPECT_EQ(SurfaceNormals(scatter, 50.0f).planes(), 0u);
}

TEST(MatchInformation, ACornerPinsEveryDirectionATunnelLeavesTheSlideFree) {
  std::vector<Eigen::Vector3f> corner;
  const Eigen::Vector3f x = Eigen::Vector3f::UnitX(), y = Eigen::Vector3f::UnitY(), z = Eigen::Vector3f::UnitZ();
  add_plane(corner, {0.0f, 0.0f, 0.0f}, x, y, 300.0f);
  add_plane(corner, {0.0f, 0.0f, 0.0f}, y, z, 300.0f);
  add_plane(corner, {0.0f, 0.0f, 0.0f}, x, z, 300.0f);
  std::size_t pairs = 0;
  const Matrix6d boxed = point_to_plane_information(corner, SurfaceNormals(corner, 50.0f), &pairs);
  EXPECT_GT(pairs, corner.size() / 2);
  EXPECT_GT(translation_constraint_ratio(boxed), 0.5);

  const std::vector<Eigen::Vector3f> smooth = tunnel();
  const Matrix6d sliding = point_to_plane_information(smooth, SurfaceNormals(smooth, 50.0f));
  EXPECT_LT(translation_constraint_ratio(sliding), 1e-3);
  EXPECT_LT(sliding(2, 2), 1e-3 * sliding(0, 0));  // nothing along the tunnel
  EXPECT_TRUE(point_to_plane_information({}, SurfaceNormals(smooth, 50.0f)).isZero());
}

// Turns about the scan's origin: a corner's surfaces pin every axis; a round tube seen from its
// axis pins every turn but the one about that axis (a forward-looking sensor in a round drive);
// the flat ribs, floor and roof of the square tunnel pin that one too.
TEST(MatchInformation, ARoundTubeLeavesTheTurnAboutItsAxisFree) {
  std::vector<Eigen::Vector3f> corner;
  const Eigen::Vector3f x = Eigen::Vector3f::UnitX(), y = Eigen::Vector3f::UnitY(), z = Eigen::Vector3f::UnitZ();
  add_plane(corner, {100.0f, 100.0f, 100.0f}, x, y, 300.0f);
  add_plane(corner, {100.0f, 100.0f, 100.0f}, y, z, 300.0f);
  add_plane(corner, {100.0f, 100.0f, 100.0f}, x, z, 300.0f);
  const double cornered = rotation_constraint_ratio(point_to_plane_information(corner, SurfaceNormals(corner, 50.0f)));

  std::vector<Eigen::Vector3f> tube;  // radius 200 cm about z, 2000 cm long, points 5 cm apart
  for (float along = -1000.0f; along < 1000.0f; along += 5.0f) {
    for (int k = 0; k < 250; ++k) {
      const float a = 2.0f * float(M_PI) * float(k) / 250.0f;
      tube.push_back({200.0f * std::cos(a), 200.0f * std::sin(a), along});
    }
  }
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();
  const Matrix6d round = point_to_plane_information(tube, SurfaceNormals(tube, 50.0f));
  const double tubed = rotation_constraint_ratio(round, &axis);
  EXPECT_NEAR(std::abs(axis.z()), 1.0, 1e-3);
  const std::vector<Eigen::Vector3f> square = tunnel();
  const double squared = rotation_constraint_ratio(point_to_plane_information(square, SurfaceNormals(square, 50.0f)));
  std::printf("turn constraints: corner %.4f, round tube %.5f, square tunnel %.4f\n", cornered, tubed, squared);
  // The tube's is its cells' normals' error (planes fitted to a curved wall): about 40 times below the others.
  EXPECT_LT(tubed, 0.05 * cornered);
  EXPECT_LT(tubed, 0.05 * squared);
}

// A chain of two steps and a loop edge that disagrees with it by 10 cm along x. With every edge
// alike, both steps take half of the gap; when the first step's match could not see x (a slide),
// that step takes nearly all of it and the other keeps what its match measured.
TEST(MatchInformation, TheRelaxationBendsTheStepThatCouldNotSee) {
  const auto at = [](double x, double z) {
    Pose p = Pose::Identity();
    p(0, 3) = x;
    p(2, 3) = z;
    return p;
  };
  const std::vector<Pose> poses{at(0, 0), at(0, 400), at(0, 800)};
  std::vector<PoseGraphEdge> edges{{0, 1, at(0, 400)}, {1, 2, at(0, 400)}, {0, 2, at(10, 800)}};
  const auto step_x = [](const PoseGraphResult& r, std::size_t k) {
    return (rigid_inverse(r.poses[k - 1]) * r.poses[k])(0, 3);
  };
  const PoseGraphResult alike = optimise_pose_graph(poses, edges, 0);
  EXPECT_NEAR(step_x(alike, 1), step_x(alike, 2), 0.5);

  Matrix6d blind_x = Matrix6d::Identity();
  blind_x.bottomRightCorner<3, 3>() *= 250000.0;  // (0.002 rad)^-2
  blind_x(0, 0) = 0.01;
  edges[0].information = blind_x;
  const PoseGraphResult shaped = optimise_pose_graph(poses, edges, 0);
  EXPECT_GT(step_x(shaped, 1), 9.0);
  EXPECT_LT(std::abs(step_x(shaped, 2)), 1.0);

  edges[0].information(0, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(optimise_pose_graph(poses, edges, 0), std::invalid_argument);
}

}  // namespace
}  // namespace minemap
