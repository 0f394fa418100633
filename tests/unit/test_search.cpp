// Closest-point search against a brute-force oracle, on both backends. Distances are compared,
// never indices (ties are legal).
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>
#include <thread>

#include "minemap/backend/compute_backend.hpp"
#include "minemap/search/kdtree.hpp"
#include "minemap/search/pairing.hpp"
#include "minemap/search/pairing_math.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

using test::random_cloud;

/// The oracle: smallest squared distance from q to any point, in double.
double oracle_squared_distance(const std::vector<Eigen::Vector3f>& model, const Eigen::Vector3f& q) {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& m : model) best = std::min(best, (m.cast<double>() - q.cast<double>()).squaredNorm());
  return best;
}

using test::backend_named;  // "opencl" throws (the test fails) without OpenCL

class SearchTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override { backend_ = backend_named(GetParam()); }
  std::unique_ptr<ComputeBackend> backend_;
};

TEST_P(SearchTest, ExactMatchesBruteForceOracleOnRandomCloud) {
  const auto model_points = random_cloud(5000, -500.f, 500.f, 1);
  const auto query_points = random_cloud(2000, -550.f, 550.f, 2);
  auto model = backend_->prepare(model_points, {});
  auto data = backend_->prepare(query_points, {});
  const ModelPlacement placement{model.get(), Pose::Identity()};
  const float max_dist = 60.0f;
  for (auto method : {SearchMethod::kExact, SearchMethod::kBruteForce}) {
    const auto pairs = backend_->nearest(*data, {&placement, 1}, method, {max_dist});
    int paired = 0;
    for (std::size_t i = 0; i < query_points.size(); ++i) {
      const double expected = oracle_squared_distance(model_points, query_points[i]);
      if (expected < max_dist * max_dist * 0.999) {
        ASSERT_GE(pairs[i].squared_distance_cm2, 0.0f) << "query " << i << " should pair (" << to_string(method) << ")";
        EXPECT_NEAR(pairs[i].squared_distance_cm2, expected, 1e-3 * (1.0 + expected)) << "query " << i;
        const auto& hit = model_points[static_cast<std::size_t>(pairs[i].model_point)];
        EXPECT_NEAR((hit - pairs[i].position_cm).norm(), 0.0, 1e-3);
        ++paired;
      } else if (expected > max_dist * max_dist * 1.001) {
        EXPECT_LT(pairs[i].squared_distance_cm2, 0.0f) << "query " << i << " is beyond the bound";
      }
    }
    EXPECT_GT(paired, 500);
  }
}

TEST_P(SearchTest, ApproximateReturnsTheMeanOfTheQueryLeaf) {
  const auto model_points = random_cloud(3000, 0.f, 1000.f, 3);
  const auto query_points = random_cloud(500, 0.f, 1000.f, 4);
  auto model = backend_->prepare(model_points, {});
  auto data = backend_->prepare(query_points, {});
  const ModelPlacement placement{model.get(), Pose::Identity()};
  const auto pairs = backend_->nearest(*data, {&placement, 1}, SearchMethod::kApproximate, {1e6f});
  const KdTree& tree = model->tree();
  for (std::size_t i = 0; i < query_points.size(); ++i) {
    // Descend by hand to the leaf whose region holds the query, then average its bucket.
    std::int32_t node = 0;
    while (tree.nodes()[node].axis != KdNode::kLeaf) {
      const auto& n = tree.nodes()[node];
      node = query_points[i][n.axis] < std::bit_cast<float>(n.split_bits) ? n.a : n.b;
    }
    const auto& leaf = tree.nodes()[node];
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (int k = leaf.a; k < leaf.a + leaf.b; ++k) {
      const auto& p = tree.points()[k];
      mean += Eigen::Vector3d(p.x, p.y, p.z);
    }
    mean /= leaf.b;
    ASSERT_GE(pairs[i].squared_distance_cm2, 0.0f);
    EXPECT_NEAR((pairs[i].position_cm.cast<double>() - mean).norm(), 0.0, 1e-3) << "query " << i;
    EXPECT_EQ(pairs[i].model_point, -1);
  }
}

TEST_P(SearchTest, EdgeCases) {
  // Fewer points than a bucket, duplicates, points on cut planes, far queries, tiny bound.
  std::vector<Eigen::Vector3f> few = {{0, 0, 0}, {10, 0, 0}, {10, 0, 0}, {5, 5, 5}};
  std::vector<Eigen::Vector3f> grid;
  for (int x = 0; x < 20; ++x)
    for (int y = 0; y < 20; ++y) grid.emplace_back(static_cast<float>(x) * 10.f, static_cast<float>(y) * 10.f, 0.f);
  for (int d = 0; d < 50; ++d) grid.emplace_back(50.f, 50.f, 0.f);  // duplicates of a grid point
  std::vector<Eigen::Vector3f> queries = {{0, 0, 0}, {5, 0, 0}, {95, 95, 0}, {45, 45, 0}, {1e5f, 0, 0}, {50, 50, 0}};
  for (const auto* model_points : {&few, &grid}) {
    auto model = backend_->prepare(*model_points, {});
    auto data = backend_->prepare(queries, {});
    const ModelPlacement placement{model.get(), Pose::Identity()};
    const auto pairs = backend_->nearest(*data, {&placement, 1}, SearchMethod::kExact, {100.f});
    for (std::size_t i = 0; i < queries.size(); ++i) {
      const double expected = oracle_squared_distance(*model_points, queries[i]);
      if (expected < 100.0 * 100.0) {
        EXPECT_NEAR(pairs[i].squared_distance_cm2, expected, 1e-3) << "query " << i;
      } else {
        EXPECT_LT(pairs[i].squared_distance_cm2, 0.f) << "query " << i;
      }
    }
    const auto none = backend_->nearest(*data, {&placement, 1}, SearchMethod::kExact, {1e-4f});
    EXPECT_LT(none[1].squared_distance_cm2, 0.f);  // bound smaller than every distance
  }
}

TEST_P(SearchTest, APileOfCopiesGivesTheFirstCopyAsBruteForceDoes) {
  // A LiDAR's no-return points pile up at its origin; the tree scans one copy of such a bucket.
  auto model_points = random_cloud(2000, -500.f, 500.f, 21);
  model_points.insert(model_points.begin() + 700, 600, Eigen::Vector3f::Zero());
  auto query_points = random_cloud(300, -30.f, 30.f, 22);
  query_points.insert(query_points.end(), 50, Eigen::Vector3f::Zero());
  auto model = backend_->prepare(model_points, {});
  auto data = backend_->prepare(query_points, {});
  const ModelPlacement placement{model.get(), Pose::Identity()};
  const auto exact = backend_->nearest(*data, {&placement, 1}, SearchMethod::kExact, {40.f});
  const auto brute = backend_->nearest(*data, {&placement, 1}, SearchMethod::kBruteForce, {40.f});
  int at_the_pile = 0;
  for (std::size_t i = 0; i < query_points.size(); ++i) {
    EXPECT_EQ(exact[i].squared_distance_cm2, brute[i].squared_distance_cm2) << "query " << i;
    EXPECT_EQ(exact[i].model_point, brute[i].model_point) << "query " << i;
    at_the_pile += exact[i].model_point >= 700 && exact[i].model_point < 1300 ? 1 : 0;
  }
  EXPECT_GE(at_the_pile, 50);  // the zero queries at least
}

TEST_P(SearchTest, EmptyModelAndEmptyData) {
  auto empty = backend_->prepare({}, {});
  auto cloud = backend_->prepare(random_cloud(100, 0.f, 10.f, 5), {});
  const ModelPlacement to_empty{empty.get(), Pose::Identity()};
  const auto sums = backend_->pair_and_sum(*cloud, {&to_empty, 1}, SearchMethod::kExact, {25.f});
  EXPECT_EQ(sums.count, 0.0);
  const ModelPlacement to_cloud{cloud.get(), Pose::Identity()};
  EXPECT_EQ(backend_->pair_and_sum(*empty, {&to_cloud, 1}, SearchMethod::kExact, {25.f}).count, 0.0);
}

TEST_P(SearchTest, UnionOfModelsFindsTheClosestOverAll) {
  // Two model clouds placed apart; the union must give the closest point over both.
  const auto a = random_cloud(2000, 0.f, 300.f, 6);
  const auto b = random_cloud(2000, 0.f, 300.f, 7);
  const auto q = random_cloud(1000, 0.f, 600.f, 8);
  auto ma = backend_->prepare(a, {});
  auto mb = backend_->prepare(b, {});
  auto data = backend_->prepare(q, {});
  Pose b_from_data = Pose::Identity();
  b_from_data(0, 3) = -300.0;  // model b occupies x in [300, 600] of the data frame
  const std::vector<ModelPlacement> models = {{ma.get(), Pose::Identity()}, {mb.get(), b_from_data}};
  const auto pairs = backend_->nearest(*data, models, SearchMethod::kExact, {30.f});
  std::vector<Eigen::Vector3f> both = a;
  for (const auto& p : b) both.emplace_back(p.x() + 300.f, p.y(), p.z());
  for (std::size_t i = 0; i < q.size(); ++i) {
    const double expected = oracle_squared_distance(both, q[i]);
    if (expected < 30.0 * 30.0 * 0.999) {
      ASSERT_GE(pairs[i].squared_distance_cm2, 0.f);
      EXPECT_NEAR(pairs[i].squared_distance_cm2, expected, 1e-2 * (1 + expected));
    }
  }
}

// A skip (ModelPlacement::skip) leaves a run of a model's points out, as if the tree never held
// them: the exact search finds the nearest of the others (the brute force over them), never one
// it left out, also where the left-out points crowd round every query (a judged scan's own points
// in its block's tree), and pair_and_sum pairs as the union without them would. Only the exact
// search takes one.
TEST_P(SearchTest, ASkipLeavesItsPointsOutOfTheExactSearch) {
  // Points 1000-2999 (a scan in the middle of a block) lie round the queries; the others farther.
  std::vector<Eigen::Vector3f> model = random_cloud(1000, -500.f, 500.f, 31);
  const std::vector<Eigen::Vector3f> queries = random_cloud(1500, -400.f, 400.f, 32);
  for (std::size_t k = 0; k < 2000; ++k) model.push_back(queries[k % queries.size()] + Eigen::Vector3f(0.3f, 0.0f, 0.0f));
  const std::vector<Eigen::Vector3f> after = random_cloud(1000, -500.f, 500.f, 33);
  model.insert(model.end(), after.begin(), after.end());
  auto tree = backend_->prepare(model, {});
  auto data = backend_->prepare(queries, {});
  const SkippedPoints skip{1000, 2000};
  std::vector<Eigen::Vector3f> kept(model.begin(), model.begin() + 1000);
  kept.insert(kept.end(), after.begin(), after.end());
  auto without = backend_->prepare(kept, {});
  const ModelPlacement skipping{tree.get(), Pose::Identity(), skip};
  const ModelPlacement plain{without.get(), Pose::Identity()};
  const float bound = 80.0f;
  const auto pairs = backend_->nearest(*data, {&skipping, 1}, SearchMethod::kExact, {bound});
  const auto expected = backend_->nearest(*data, {&plain, 1}, SearchMethod::kExact, {bound});
  int paired = 0;
  for (std::size_t i = 0; i < queries.size(); ++i) {
    const double oracle = oracle_squared_distance(kept, queries[i]);
    if (oracle < bound * bound * 0.999) {
      ASSERT_GE(pairs[i].squared_distance_cm2, 0.0f) << "query " << i;
      EXPECT_NEAR(pairs[i].squared_distance_cm2, oracle, 1e-3 * (1.0 + oracle)) << "query " << i;
      EXPECT_FALSE(skip.leaves_out(pairs[i].model_point)) << "query " << i << " paired a point left out";
      ++paired;
    } else if (oracle > bound * bound * 1.001) {
      EXPECT_LT(pairs[i].squared_distance_cm2, 0.0f) << "query " << i;
    }
    // The same points, so the same distances bit for bit as the tree without them.
    EXPECT_EQ(pairs[i].squared_distance_cm2, expected[i].squared_distance_cm2) << "query " << i;
  }
  EXPECT_GT(paired, 300);
  const PairSums sums = backend_->pair_and_sum(*data, {&skipping, 1}, SearchMethod::kExact, {bound});
  const PairSums sums_without = backend_->pair_and_sum(*data, {&plain, 1}, SearchMethod::kExact, {bound});
  EXPECT_EQ(sums.count, double(paired));
  EXPECT_EQ(sums.count, sums_without.count);
  EXPECT_EQ(sums.sum_squared_distance_cm2, sums_without.sum_squared_distance_cm2);
  EXPECT_EQ(sums.sum_data_model, sums_without.sum_data_model);
  // With no skip the crowding points are found (the skip did the leaving out).
  const ModelPlacement whole{tree.get(), Pose::Identity()};
  const auto all = backend_->nearest(*data, {&whole, 1}, SearchMethod::kExact, {bound});
  EXPECT_TRUE(skip.leaves_out(all[0].model_point));
  for (auto method : {SearchMethod::kApproximate, SearchMethod::kBruteForce}) {
    EXPECT_THROW(backend_->nearest(*data, {&skipping, 1}, method, {bound}), std::invalid_argument) << to_string(method);
    EXPECT_THROW(backend_->pair_and_sum(*data, {&skipping, 1}, method, {bound}), std::invalid_argument) << to_string(method);
  }
}

TEST_P(SearchTest, SumsMatchDoubleReferenceFarFromOrigin) {
  // A cloud 1 km from the origin: centred sums keep full accuracy.
  auto model_points = random_cloud(20000, -500.f, 500.f, 9);
  for (auto& p : model_points) p += Eigen::Vector3f(100000.f, 0.f, 50000.f);
  std::vector<Eigen::Vector3f> data_points;
  for (std::size_t i = 0; i < model_points.size(); i += 2) data_points.push_back(model_points[i] + Eigen::Vector3f(1.f, 2.f, -1.f));
  auto model = backend_->prepare(model_points, {});
  auto data = backend_->prepare(data_points, {});
  const ModelPlacement placement{model.get(), Pose::Identity()};
  const auto sums = backend_->pair_and_sum(*data, {&placement, 1}, SearchMethod::kExact, {25.f});
  const auto pairs = make_cpu_backend()->nearest(*data, {&placement, 1}, SearchMethod::kExact, {25.f});
  PairSums reference;
  reference.reference_cm = sums.reference_cm;  // the reference the backend centred on
  double magnitude = 0.0;                      // sum of |p'|: the scale float round-off works at
  for (std::size_t i = 0; i < data_points.size(); ++i) {
    if (pairs[i].squared_distance_cm2 < 0) continue;
    const Eigen::Vector3d p = data_points[i].cast<double>() - reference.reference_cm;
    const Eigen::Vector3d m = pairs[i].position_cm.cast<double>() - reference.reference_cm;
    reference.count += 1;
    reference.sum_data += p;
    reference.sum_model += m;
    reference.sum_data_model += p * m.transpose();
    reference.sum_squared_distance_cm2 += (p - m).squaredNorm();
    magnitude += p.norm();
  }
  ASSERT_GT(reference.count, 1000);
  EXPECT_EQ(sums.count, reference.count);
  const double scale = reference.sum_data_model.norm();
  EXPECT_LT((sums.sum_data_model - reference.sum_data_model).norm() / scale, 1e-6);
  EXPECT_LT((sums.sum_data - reference.sum_data).norm() / magnitude, 1e-6);
  EXPECT_LT((sums.sum_model - reference.sum_model).norm() / magnitude, 1e-6);
  EXPECT_NEAR(sums.sum_squared_distance_cm2 / reference.sum_squared_distance_cm2, 1.0, 1e-5);
}

TEST_P(SearchTest, RobustSumsWeighEachPairByTheGemanMcClureKernel) {
  // PairingSettings::robust_scale_cm: every pair's terms times w = (s^2 / (s^2 + d^2))^2, written
  // here from its definition (not shared::mm_robust_weight), over the brute force's pairs; the count
  // and the squared distances stay unweighted. A scale of 0 is the plain sums, bit for bit.
  const auto model_points = random_cloud(6000, -300.f, 300.f, 21);
  auto data_points = random_cloud(3000, -300.f, 300.f, 22);
  auto model = backend_->prepare(model_points, {});
  auto data = backend_->prepare(data_points, {});
  const ModelPlacement placement{model.get(), Pose::Identity()};
  const float bound = 30.f, scale = 10.f;
  const auto pairs = make_cpu_backend()->nearest(*data, {&placement, 1}, SearchMethod::kBruteForce, {bound});
  for (auto method : {SearchMethod::kExact, SearchMethod::kBruteForce}) {
    const PairSums sums = backend_->pair_and_sum(*data, {&placement, 1}, method, {bound, scale});
    PairSums expected;
    double magnitude = 0.0;
    for (std::size_t i = 0; i < data_points.size(); ++i) {
      if (pairs[i].squared_distance_cm2 < 0) continue;
      const Eigen::Vector3d p = data_points[i].cast<double>() - sums.reference_cm;
      const Eigen::Vector3d m = pairs[i].position_cm.cast<double>() - sums.reference_cm;
      const double d2 = pairs[i].squared_distance_cm2, s2 = double(scale) * scale;
      const double w = (s2 / (s2 + d2)) * (s2 / (s2 + d2));
      expected.count += 1.0;
      expected.weight += w;
      expected.sum_data += w * p;
      expected.sum_model += w * m;
      expected.sum_data_model += w * p * m.transpose();
      expected.sum_squared_distance_cm2 += d2;
      magnitude += p.norm();
    }
    ASSERT_GT(expected.count, 1000);
    EXPECT_EQ(sums.count, expected.count) << to_string(method);
    EXPECT_LT(expected.weight, 0.9 * expected.count);  // the kernel weighs far pairs down
    EXPECT_NEAR(sums.weight / expected.weight, 1.0, 1e-6) << to_string(method);
    EXPECT_NEAR(sums.sum_squared_distance_cm2 / expected.sum_squared_distance_cm2, 1.0, 1e-6);
    EXPECT_LT((sums.sum_data - expected.sum_data).norm() / magnitude, 1e-6) << to_string(method);
    EXPECT_LT((sums.sum_model - expected.sum_model).norm() / magnitude, 1e-6) << to_string(method);
    EXPECT_LT((sums.sum_data_model - expected.sum_data_model).norm() / expected.sum_data_model.norm(), 1e-6);
    // Scale 0: every pair weighs exactly 1.
    const PairSums plain = backend_->pair_and_sum(*data, {&placement, 1}, method, {bound});
    const PairSums zero = backend_->pair_and_sum(*data, {&placement, 1}, method, {bound, 0.f});
    EXPECT_EQ(plain.weight, plain.count);
    EXPECT_EQ(zero.sum_data_model, plain.sum_data_model);
    EXPECT_EQ(zero.sum_data, plain.sum_data);
  }
}

TEST_P(SearchTest, SumsAreBitIdenticalRunToRun) {
  const auto cloud = random_cloud(30000, 0.f, 2000.f, 10);
  auto model = backend_->prepare(cloud, {});
  auto data = backend_->prepare(random_cloud(30000, 0.f, 2000.f, 11), {});
  const ModelPlacement placement{model.get(), Pose::Identity()};
  const auto first = backend_->pair_and_sum(*data, {&placement, 1}, SearchMethod::kExact, {25.f});
  const auto second = backend_->pair_and_sum(*data, {&placement, 1}, SearchMethod::kExact, {25.f});
  EXPECT_EQ(first.count, second.count);
  EXPECT_EQ(first.sum_data_model, second.sum_data_model);
  EXPECT_EQ(first.sum_squared_distance_cm2, second.sum_squared_distance_cm2);
}

TEST_P(SearchTest, ATreeBuiltOnFirstUseIsTheTreeBuiltAtOnce) {
  // A sweep's clouds are prepared with TreeBuild::kOnFirstUse: the same bounds before any tree
  // exists, and the same tree, pairs and distances once one is searched, from several threads at once.
  const auto model_points = random_cloud(4000, -300.f, 300.f, 11);
  const auto query_points = random_cloud(1500, -320.f, 320.f, 12);
  auto now = backend_->prepare(model_points, {}, TreeBuild::kNow);
  auto later = backend_->prepare(model_points, {}, TreeBuild::kOnFirstUse);
  EXPECT_EQ(later->bounds_min(), now->bounds_min());
  EXPECT_EQ(later->bounds_max(), now->bounds_max());
  EXPECT_EQ(later->bounds_min(), now->tree().bounds_min());
  EXPECT_EQ(later->bounds_max(), now->tree().bounds_max());
  EXPECT_EQ(later->centroid_cm(), now->centroid_cm());
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) threads.emplace_back([&] { (void)later->tree().size(); });
  for (auto& thread : threads) thread.join();
  ASSERT_EQ(later->tree().size(), now->tree().size());
  for (std::size_t k = 0; k < now->tree().size(); ++k) {
    EXPECT_EQ(later->tree().points()[k].original_index, now->tree().points()[k].original_index);
  }
  auto data = backend_->prepare(query_points, {});
  const ModelPlacement at_once{now.get(), Pose::Identity()}, on_first_use{later.get(), Pose::Identity()};
  for (auto method : {SearchMethod::kExact, SearchMethod::kApproximate}) {
    const auto expected = backend_->nearest(*data, {&at_once, 1}, method, {40.0f});
    const auto found = backend_->nearest(*data, {&on_first_use, 1}, method, {40.0f});
    for (std::size_t i = 0; i < expected.size(); ++i) {
      EXPECT_EQ(found[i].squared_distance_cm2, expected[i].squared_distance_cm2) << "query " << i;
      EXPECT_EQ(found[i].model_point, expected[i].model_point) << "query " << i;
    }
  }
  auto empty = backend_->prepare({}, {}, TreeBuild::kOnFirstUse);
  EXPECT_TRUE(empty->empty());
  EXPECT_EQ(empty->bounds_min(), Eigen::Vector3f::Zero());
  EXPECT_TRUE(empty->tree().empty());
}

INSTANTIATE_TEST_SUITE_P(Backends, SearchTest, ::testing::Values("cpu", "opencl"));

TEST(SearchBackends, CpuAndOpenClFindTheSameDistances) {
  auto cpu = make_cpu_backend();
  auto device = test::opencl_backend();
  const auto model_points = random_cloud(20000, -1000.f, 1000.f, 12);
  const auto query_points = random_cloud(10000, -1000.f, 1000.f, 13);
  Pose placement_pose = euler_to_pose({Eigen::Vector3d(12.0, -7.0, 30.0), Eigen::Vector3d(1.0, -2.0, 3.0)});
  auto cm = cpu->prepare(model_points, {});
  auto cd = cpu->prepare(query_points, {});
  auto gm = device->prepare(model_points, {});
  auto gd = device->prepare(query_points, {});
  for (auto method : {SearchMethod::kExact, SearchMethod::kApproximate, SearchMethod::kBruteForce}) {
    const ModelPlacement cp{cm.get(), placement_pose};
    const ModelPlacement gp{gm.get(), placement_pose};
    const auto a = cpu->nearest(*cd, {&cp, 1}, method, {40.f});
    const auto b = device->nearest(*gd, {&gp, 1}, method, {40.f});
    int mismatches = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
      if (a[i].squared_distance_cm2 != b[i].squared_distance_cm2) ++mismatches;
    }
    // Contraction is off in the kernels and the C++ build: the distances agree bit for bit.
    EXPECT_EQ(mismatches, 0) << to_string(method);
  }
  // The robust sums (PairingSettings::robust_scale_cm) are the same bits on both backends where
  // the device sums in double (the opencl_float_sums run, MINEMAP_OPENCL_FP64=off, sums in float).
  {
    const char* fp64 = std::getenv("MINEMAP_OPENCL_FP64");
    const bool float_sums = fp64 != nullptr && std::string(fp64) == "off";
    const ModelPlacement cp{cm.get(), placement_pose};
    const ModelPlacement gp{gm.get(), placement_pose};
    const PairSums a = cpu->pair_and_sum(*cd, {&cp, 1}, SearchMethod::kExact, {40.f, 13.f});
    const PairSums b = device->pair_and_sum(*gd, {&gp, 1}, SearchMethod::kExact, {40.f, 13.f});
    EXPECT_GT(a.count, 100.0);
    EXPECT_LT(a.weight, a.count);
    EXPECT_EQ(a.count, b.count);
    if (float_sums) {
      EXPECT_NEAR(b.weight / a.weight, 1.0, 1e-5);
      EXPECT_LT((a.sum_data_model - b.sum_data_model).norm() / a.sum_data_model.norm(), 1e-5);
    } else {
      EXPECT_EQ(a.weight, b.weight);
      EXPECT_EQ(a.sum_data, b.sum_data);
      EXPECT_EQ(a.sum_model, b.sum_model);
      EXPECT_EQ(a.sum_data_model, b.sum_data_model);
    }
  }
  // ... and with a run of the model's points left out (SkippedPoints), the same points found.
  const ModelPlacement cp{cm.get(), placement_pose, {5000, 7000}};
  const ModelPlacement gp{gm.get(), placement_pose, {5000, 7000}};
  const auto a = cpu->nearest(*cd, {&cp, 1}, SearchMethod::kExact, {40.f});
  const auto b = device->nearest(*gd, {&gp, 1}, SearchMethod::kExact, {40.f});
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].squared_distance_cm2, b[i].squared_distance_cm2) << "query " << i;
    ASSERT_EQ(a[i].model_point, b[i].model_point) << "query " << i;
  }
}

TEST(KdTree, BucketsHoldAtMostBucketSizePointsAndCutInHalves) {
  const auto cloud = random_cloud(10000, 0.f, 100.f, 14);
  for (int bucket : {1, 10, 100}) {
    KdTree tree(cloud, {bucket});
    std::size_t total = 0;
    for (const auto& node : tree.nodes()) {
      if (node.axis == KdNode::kLeaf) {
        EXPECT_LE(node.b, bucket);
        total += static_cast<std::size_t>(node.b);
      }
    }
    EXPECT_EQ(total, cloud.size());
  }
  // All-duplicate input ends in one oversized bucket instead of infinite recursion, searched as
  // its first point (the first of equals wins anyway); its mean still counts every copy.
  std::vector<Eigen::Vector3f> same(1000, Eigen::Vector3f(1, 2, 3));
  KdTree dup(same, {10});
  ASSERT_EQ(dup.nodes().size(), 1u);
  EXPECT_EQ(dup.nodes()[0].b, 1);
  EXPECT_EQ(dup.leaf_means()[0][3], 1000.0f);
  // Near copies that no cut can separate (adjacent floats) are not copies: all of them are scanned.
  std::vector<Eigen::Vector3f> near_copies(30, Eigen::Vector3f(1, 2, 3));
  near_copies[17].x() = std::nextafter(1.0f, 2.0f);
  KdTree near(near_copies, {10});
  std::size_t scanned = 0;
  for (const auto& node : near.nodes()) scanned += node.axis == KdNode::kLeaf ? static_cast<std::size_t>(node.b) : 0;
  EXPECT_EQ(scanned, near_copies.size());
}

// The CPU backend starts each exact search from the previous query's closest point as a bound.
// That must never change the answer: the same point (ties included) as the unhinted search, which
// the OpenCL kernel runs, for any hint at all.
TEST(KdTree, HintedExactSearchReturnsTheUnhintedPoint) {
  auto cloud = random_cloud(5000, 0.f, 200.f, 21);
  // Duplicates and points on a lattice make exact ties in float distance common.
  for (int i = 0; i < 500; ++i) cloud.push_back(cloud[static_cast<std::size_t>(i)]);
  for (int i = 0; i < 500; ++i) cloud.emplace_back(static_cast<float>(i % 10) * 4.f, static_cast<float>(i / 10 % 10) * 4.f, 0.f);
  const auto queries = random_cloud(3000, -10.f, 210.f, 22);
  KdTree tree(cloud, {10});
  int ties_or_hits = 0;
  for (std::size_t i = 0; i < queries.size(); ++i) {
    Eigen::Vector3f q = queries[i];
    if (i % 3 == 0) q = Eigen::Vector3f(static_cast<float>(i % 40), static_cast<float>(i % 37), 0.f);  // on the lattice
    float plain_best = 25.f * 25.f;
    std::int32_t plain = -1;
    detail::exact_nearest(tree, q, plain_best, plain);
    for (std::int32_t hint : {0, static_cast<std::int32_t>(i % tree.size()), plain >= 0 ? plain : 1}) {
      float best = 25.f * 25.f;
      std::int32_t hit = -1;
      detail::exact_nearest(tree, q, best, hit, hint);
      ASSERT_EQ(hit, plain) << "query " << i << " hint " << hint;
      if (hit >= 0) {
        EXPECT_EQ(std::bit_cast<std::uint32_t>(best), std::bit_cast<std::uint32_t>(plain_best));
        ++ties_or_hits;
      }
    }
  }
  EXPECT_GT(ties_or_hits, 1000);
}

}  // namespace
}  // namespace minemap
