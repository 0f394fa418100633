// Horn's closed-form absolute orientation and the ICP loop (paper, section IV.A, with the
// approximate-then-exact schedule of section IV.D). Oracles: exact correspondences of a known
// transform, an independent SVD (Kabsch) least-squares solution in double, Horn's 1987 N matrix
// written out, its quadratic form, and brute-force pair counting.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "minemap/core/pose.hpp"
#include "minemap/filter/slice_filter.hpp"
#include "minemap/registration/horn.hpp"
#include "minemap/registration/icp.hpp"
#include "minemap/registration/match_information.hpp"
#include "minemap/search/pairing.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// ---------------------------------------------------------------------------------------------
// Helpers

Pose make_pose(const Eigen::Matrix3d& r, const Eigen::Vector3d& t) {
  Pose p = Pose::Identity();
  p.block<3, 3>(0, 0) = r;
  p.block<3, 1>(0, 3) = t;
  return p;
}

Eigen::Vector3d apply(const Pose& t, const Eigen::Vector3d& p) { return t.block<3, 3>(0, 0) * p + t.block<3, 1>(0, 3); }

Eigen::Matrix3d axis_angle(const Eigen::Vector3d& axis, double angle_rad) {
  return Eigen::AngleAxisd(angle_rad, axis.normalized()).toRotationMatrix();
}

/// A uniformly random rotation (Shoemake: normalised 4D Gaussian).
Eigen::Matrix3d random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  return q.normalized().toRotationMatrix();
}

/// The sums a backend would produce for pairs (p_i, m_i) in the data frame, centred on `r`.
PairSums sums_from_pairs(const std::vector<Eigen::Vector3d>& data, const std::vector<Eigen::Vector3d>& model,
                         const Eigen::Vector3d& r) {
  PairSums s;
  s.reference_cm = r;
  for (std::size_t i = 0; i < data.size(); ++i) {
    const Eigen::Vector3d p = data[i] - r, m = model[i] - r;
    s.count += 1.0;
    s.weight += 1.0;
    s.sum_data += p;
    s.sum_model += m;
    s.sum_data_model += p * m.transpose();
    s.sum_squared_distance_cm2 += (p - m).squaredNorm();
  }
  return s;
}

/// Independent weighted least-squares rigid fit (weighted Kabsch via SVD, in double): minimises
/// sum w_i |m_i - (R p_i + t)|^2.
Pose weighted_kabsch(const std::vector<Eigen::Vector3d>& data, const std::vector<Eigen::Vector3d>& model,
                     const std::vector<double>& w) {
  Eigen::Vector3d cp = Eigen::Vector3d::Zero(), cm = Eigen::Vector3d::Zero();
  double total = 0.0;
  for (std::size_t i = 0; i < data.size(); ++i) {
    cp += w[i] * data[i];
    cm += w[i] * model[i];
    total += w[i];
  }
  cp /= total;
  cm /= total;
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < data.size(); ++i) h += w[i] * (data[i] - cp) * (model[i] - cm).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  const Eigen::Matrix3d r = svd.matrixV() * d * svd.matrixU().transpose();
  return make_pose(r, cm - r * cp);
}

/// Independent least-squares rigid fit (Kabsch/Umeyama via SVD, in double, from the raw points).
Pose kabsch(const std::vector<Eigen::Vector3d>& data, const std::vector<Eigen::Vector3d>& model) {
  Eigen::Vector3d cp = Eigen::Vector3d::Zero(), cm = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < data.size(); ++i) {
    cp += data[i];
    cm += model[i];
  }
  cp /= double(data.size());
  cm /= double(data.size());
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < data.size(); ++i) h += (data[i] - cp) * (model[i] - cm).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  const Eigen::Matrix3d r = svd.matrixV() * d * svd.matrixU().transpose();
  return make_pose(r, cm - r * cp);
}

double cost(const Pose& t, const std::vector<Eigen::Vector3d>& data, const std::vector<Eigen::Vector3d>& model) {
  double e = 0.0;
  for (std::size_t i = 0; i < data.size(); ++i) e += (model[i] - apply(t, data[i])).squaredNorm();
  return e;
}

double rotation_difference_deg(const Pose& a, const Pose& b) { return rotation_angle_deg(rigid_inverse(a) * b); }

double translation_difference_cm(const Pose& a, const Pose& b) {
  return (a.block<3, 1>(0, 3) - b.block<3, 1>(0, 3)).norm();
}

// =============================================================================================
// Horn's N matrix

/// Horn (1987), "Closed-form solution of absolute orientation using unit quaternions", section
/// 4: N written out element by element from S_ab = sum l'_a r'_b (l: data, r: model).
Eigen::Matrix4d horn_1987_n(const Eigen::Matrix3d& s) {
  const double Sxx = s(0, 0), Sxy = s(0, 1), Sxz = s(0, 2), Syx = s(1, 0), Syy = s(1, 1), Syz = s(1, 2), Szx = s(2, 0),
               Szy = s(2, 1), Szz = s(2, 2);
  Eigen::Matrix4d n;
  n(0, 0) = Sxx + Syy + Szz;
  n(0, 1) = Syz - Szy;
  n(0, 2) = Szx - Sxz;
  n(0, 3) = Sxy - Syx;
  n(1, 0) = Syz - Szy;
  n(1, 1) = Sxx - Syy - Szz;
  n(1, 2) = Sxy + Syx;
  n(1, 3) = Szx + Sxz;
  n(2, 0) = Szx - Sxz;
  n(2, 1) = Sxy + Syx;
  n(2, 2) = -Sxx + Syy - Szz;
  n(2, 3) = Syz + Szy;
  n(3, 0) = Sxy - Syx;
  n(3, 1) = Szx + Sxz;
  n(3, 2) = Syz + Szy;
  n(3, 3) = -Sxx - Syy + Szz;
  return n;
}

TEST(HornMatrix, EqualsHorn1987Definition) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1e4, 1e4);
  for (int trial = 0; trial < 100; ++trial) {
    Eigen::Matrix3d s;
    for (int i = 0; i < 9; ++i) s(i / 3, i % 3) = u(rng);
    const Eigen::Matrix4d n = horn_matrix(s);
    const Eigen::Matrix4d expected = horn_1987_n(s);
    for (int i = 0; i < 16; ++i) EXPECT_EQ(n(i / 4, i % 4), expected(i / 4, i % 4)) << "entry " << i;
    // The compact form of Besl and McKay: [[tr S, D^T], [D, S + S^T - tr(S) I]], D from S - S^T.
    Eigen::Matrix4d compact;
    const Eigen::Matrix3d a = s - s.transpose();
    const Eigen::Vector3d delta(a(1, 2), a(2, 0), a(0, 1));
    compact(0, 0) = s.trace();
    compact.block<1, 3>(0, 1) = delta.transpose();
    compact.block<3, 1>(1, 0) = delta;
    compact.block<3, 3>(1, 1) = s + s.transpose() - s.trace() * Eigen::Matrix3d::Identity();
    EXPECT_LT((n - compact).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_EQ(n, n.transpose());
    EXPECT_NEAR(n.trace(), 0.0, 1e-9);
  }
}

TEST(HornMatrix, QuadraticFormIsTheCorrelationOfRotatedPairs) {
  // Horn's derivation: for any unit quaternion q, q^T N q = sum m'_i . (R(q) p'_i). Together with
  // symmetry this determines N completely, independently of how it is written.
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> u(-300.0, 300.0);
  std::normal_distribution<double> g(0.0, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<Eigen::Vector3d> p(20), m(20);
    Eigen::Matrix3d s = Eigen::Matrix3d::Zero();
    for (int i = 0; i < 20; ++i) {
      p[i] = Eigen::Vector3d(u(rng), u(rng), u(rng));
      m[i] = Eigen::Vector3d(u(rng), u(rng), u(rng));
      s += p[i] * m[i].transpose();
    }
    const Eigen::Matrix4d n = horn_matrix(s);
    for (int k = 0; k < 10; ++k) {
      const Eigen::Quaterniond q = Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized();
      const Eigen::Vector4d qv(q.w(), q.x(), q.y(), q.z());
      double expected = 0.0;
      for (int i = 0; i < 20; ++i) expected += m[i].dot(q.toRotationMatrix() * p[i]);
      EXPECT_NEAR(qv.dot(n * qv), expected, 1e-9 * (1.0 + std::abs(expected)) + 1e-6);
    }
  }
}

// =============================================================================================
// horn_transform

const Eigen::Vector3d kFarReference(1e5, 0.0, 5e4);

struct Recovery {
  double rotation_max_abs = 0.0;   // max |R_est - R_true| entry
  double translation_cm = 0.0;     // |t_est - t_true|
  double point_residual_cm = 0.0;  // max |T_est p - m|
};

Recovery recover(const Pose& truth, std::mt19937& rng, int count, double spread_cm, bool about_reference) {
  std::uniform_real_distribution<double> u(-spread_cm, spread_cm);
  // Rotating about the reference keeps the model near it too (as in ICP, where the reference is
  // the data centroid); otherwise the transform acts about the origin, 1e5 cm away.
  const Pose t = about_reference ? make_pose(Eigen::Matrix3d::Identity(), kFarReference) * truth *
                                       make_pose(Eigen::Matrix3d::Identity(), -kFarReference)
                                 : truth;
  std::vector<Eigen::Vector3d> p, m;
  for (int i = 0; i < count; ++i) {
    p.push_back(kFarReference + Eigen::Vector3d(u(rng), u(rng), u(rng)));
    m.push_back(apply(t, p.back()));
  }
  const auto estimate = horn_transform(sums_from_pairs(p, m, kFarReference));
  Recovery r;
  if (!estimate) {
    ADD_FAILURE() << "horn_transform gave no transform";
    r.rotation_max_abs = r.translation_cm = r.point_residual_cm = INFINITY;
    return r;
  }
  EXPECT_TRUE(is_valid_rigid(*estimate, 1e-12));
  r.rotation_max_abs = (estimate->block<3, 3>(0, 0) - t.block<3, 3>(0, 0)).cwiseAbs().maxCoeff();
  r.translation_cm = translation_difference_cm(*estimate, t);
  for (std::size_t i = 0; i < p.size(); ++i) {
    r.point_residual_cm = std::max(r.point_residual_cm, (apply(*estimate, p[i]) - m[i]).norm());
  }
  return r;
}

TEST(HornTransform, RecoversKnownTransformsFromExactCorrespondences) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> t(-1000.0, 1000.0);
  std::vector<Pose> truths;
  for (int i = 0; i < 200; ++i) truths.push_back(make_pose(random_rotation(rng), {t(rng), t(rng), t(rng)}));
  // Special angles: identity, tiny, and at or next to 180 degrees (q0 = 0: the sign is free).
  const Eigen::Vector3d axis(0.3, -0.8, 0.5);
  for (double angle_deg : {0.0, 1e-7, 0.01, 90.0, 179.0, 179.99, 180.0 - 1e-6, 180.0}) {
    truths.push_back(make_pose(axis_angle(axis, angle_deg * kDeg), {t(rng), t(rng), t(rng)}));
    truths.push_back(make_pose(axis_angle(Eigen::Vector3d::UnitX(), angle_deg * kDeg), {0, 0, 0}));
    truths.push_back(make_pose(axis_angle(Eigen::Vector3d::UnitZ(), angle_deg * kDeg), {5, 0, 0}));
  }
  Recovery worst;
  double worst_relative_translation = 0.0;
  for (const auto& truth : truths) {
    const auto r = recover(truth, rng, 50, 500.0, /*about_reference=*/true);
    worst.rotation_max_abs = std::max(worst.rotation_max_abs, r.rotation_max_abs);
    worst.translation_cm = std::max(worst.translation_cm, r.translation_cm);
    // t = (c_m + r) - R (c_p + r) is formed from terms of size |r| = 1.1e5 cm (and |t| reaches
    // 2.2e5 cm), where a double ulp is 1.5e-11 .. 3e-11 cm: compare relative to that scale.
    const Pose about_r = make_pose(Eigen::Matrix3d::Identity(), kFarReference) * truth *
                         make_pose(Eigen::Matrix3d::Identity(), -kFarReference);
    worst_relative_translation =
        std::max(worst_relative_translation, r.translation_cm / (translation_norm(about_r) + kFarReference.norm()));
    worst.point_residual_cm = std::max(worst.point_residual_cm, r.point_residual_cm);
  }
  std::printf(
      "[ horn     ] exact pairs near r = (1e5, 0, 5e4): max |dR| %.2e, |dt| %.2e cm (relative %.1e), "
      "residual %.2e cm\n",
      worst.rotation_max_abs, worst.translation_cm, worst_relative_translation, worst.point_residual_cm);
  EXPECT_LT(worst.rotation_max_abs, 1e-12);
  EXPECT_LT(worst_relative_translation, 5e-14);  // a few double ulps of the scale
  EXPECT_LT(worst.translation_cm, 1e-8);
  EXPECT_LT(worst.point_residual_cm, 1e-9);
}

TEST(HornTransform, RecoversTransformsAboutTheFarOrigin) {
  // The same with the transform acting about the origin 1.1e5 cm away: the model points land up
  // to 2.2e5 cm from the reference, and forming the centred cross-covariance from the raw sums
  // loses up to log10(2.2e5 / 500) digits to cancellation (measured: residual 1e-10 cm).
  std::mt19937 rng(22);
  std::uniform_real_distribution<double> t(-1000.0, 1000.0);
  Recovery worst;
  for (int i = 0; i < 100; ++i) {
    const Pose truth = make_pose(random_rotation(rng), {t(rng), t(rng), t(rng)});
    const auto r = recover(truth, rng, 50, 500.0, /*about_reference=*/false);
    worst.rotation_max_abs = std::max(worst.rotation_max_abs, r.rotation_max_abs);
    worst.point_residual_cm = std::max(worst.point_residual_cm, r.point_residual_cm);
  }
  std::printf("[ horn     ] about the far origin: max |dR| %.2e, residual %.2e cm\n", worst.rotation_max_abs,
              worst.point_residual_cm);
  EXPECT_LT(worst.rotation_max_abs, 1e-11);
  EXPECT_LT(worst.point_residual_cm, 1e-8);
}

TEST(HornTransform, NoisyPairsGiveTheLeastSquaresOptimum) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(-400.0, 400.0), t(-50.0, 50.0);
  std::normal_distribution<double> noise(0.0, 3.0);
  double worst_rotation = 0.0, worst_translation = 0.0;
  for (int trial = 0; trial < 100; ++trial) {
    const int count = 3 + trial * 7;
    const Pose truth = make_pose(trial % 10 == 0 ? axis_angle({1, 1, 0}, 179.5 * kDeg) : random_rotation(rng),
                                 {t(rng), t(rng), t(rng)});
    const Pose about_r = make_pose(Eigen::Matrix3d::Identity(), kFarReference) * truth *
                         make_pose(Eigen::Matrix3d::Identity(), -kFarReference);
    std::vector<Eigen::Vector3d> p, m;
    for (int i = 0; i < count; ++i) {
      p.push_back(kFarReference + Eigen::Vector3d(u(rng), u(rng), u(rng)));
      m.push_back(apply(about_r, p.back()) + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
    }
    const auto estimate = horn_transform(sums_from_pairs(p, m, kFarReference));
    ASSERT_TRUE(estimate.has_value());
    const Pose optimum = kabsch(p, m);
    worst_rotation =
        std::max(worst_rotation, (estimate->block<3, 3>(0, 0) - optimum.block<3, 3>(0, 0)).cwiseAbs().maxCoeff());
    worst_translation = std::max(worst_translation, translation_difference_cm(*estimate, optimum));
    // Both are the minimiser: Horn's cost is not above the SVD's (up to round-off).
    const double e_horn = cost(*estimate, p, m), e_svd = cost(optimum, p, m);
    EXPECT_LE(e_horn, e_svd * (1.0 + 1e-9) + 1e-9) << "trial " << trial;
    // And any small perturbation costs more.
    const Pose nudged = *estimate * make_pose(axis_angle({0.2, 0.9, -0.3}, 1e-4), {0.01, 0.0, -0.01});
    EXPECT_GT(cost(nudged, p, m), e_horn) << "trial " << trial;
  }
  std::printf("[ horn     ] noisy pairs vs SVD: max |dR| %.2e, |dt| %.2e cm\n", worst_rotation, worst_translation);
  EXPECT_LT(worst_rotation, 1e-9);
  EXPECT_LT(worst_translation, 1e-7);
}

TEST(HornTransform, WeightedPairsGiveTheWeightedLeastSquaresOptimum) {
  // The robust kernel's sums (weights in (0, 1]): Horn's closed form on the weighted centroids and
  // cross-covariance is the weighted Kabsch fit; pairs that weigh next to nothing barely move it.
  std::mt19937 rng(29);
  std::uniform_real_distribution<double> u(-400.0, 400.0), t(-50.0, 50.0), weight(0.01, 1.0);
  std::normal_distribution<double> noise(0.0, 3.0);
  for (int trial = 0; trial < 50; ++trial) {
    const Pose truth = make_pose(random_rotation(rng), {t(rng), t(rng), t(rng)});
    std::vector<Eigen::Vector3d> p, m;
    std::vector<double> w;
    PairSums sums;
    sums.reference_cm = kFarReference;
    for (int i = 0; i < 10 + trial * 5; ++i) {
      p.push_back(kFarReference + Eigen::Vector3d(u(rng), u(rng), u(rng)));
      const bool outlier = i % 5 == 0;  // a wrong pair, 2 m off, that the kernel all but drops
      m.push_back(apply(truth, p.back()) + Eigen::Vector3d(noise(rng), noise(rng), noise(rng)) +
                  (outlier ? Eigen::Vector3d(200.0, -100.0, 50.0) : Eigen::Vector3d::Zero()));
      w.push_back(outlier ? 1e-6 : weight(rng));
      const Eigen::Vector3d pc = p.back() - kFarReference, mc = m.back() - kFarReference;
      sums.count += 1.0;
      sums.weight += w.back();
      sums.sum_data += w.back() * pc;
      sums.sum_model += w.back() * mc;
      sums.sum_data_model += w.back() * pc * mc.transpose();
    }
    const auto estimate = horn_transform(sums);
    ASSERT_TRUE(estimate.has_value());
    const Pose optimum = weighted_kabsch(p, m, w);
    EXPECT_LT((estimate->block<3, 3>(0, 0) - optimum.block<3, 3>(0, 0)).cwiseAbs().maxCoeff(), 1e-9) << trial;
    EXPECT_LT(translation_difference_cm(*estimate, optimum), 1e-6) << trial;
    // The outliers weigh 1e-6: the fit is the inliers' own, to a thousandth of a cm at every point.
    std::vector<Eigen::Vector3d> pi, mi;
    std::vector<double> wi;
    for (std::size_t i = 0; i < p.size(); ++i) {
      if (i % 5 == 0) continue;
      pi.push_back(p[i]);
      mi.push_back(m[i]);
      wi.push_back(w[i]);
    }
    const Pose inliers_fit = weighted_kabsch(pi, mi, wi);
    double worst = 0.0;
    for (const auto& x : p) worst = std::max(worst, (apply(*estimate, x) - apply(inliers_fit, x)).norm());
    EXPECT_LT(worst, 1e-3) << trial;
  }
}

TEST(HornTransform, DegenerateButValidGeometry) {
  std::mt19937 rng(24);
  std::uniform_real_distribution<double> u(-300.0, 300.0);
  const Pose truth = make_pose(axis_angle({0.1, 0.7, 0.2}, 37 * kDeg), {12, -40, 7});
  {
    // Coplanar points still determine the rotation.
    std::vector<Eigen::Vector3d> p, m;
    for (int i = 0; i < 30; ++i) {
      p.push_back(kFarReference + Eigen::Vector3d(u(rng), u(rng), 0.0));
      m.push_back(apply(truth, p.back()));
    }
    const auto estimate = horn_transform(sums_from_pairs(p, m, kFarReference));
    ASSERT_TRUE(estimate.has_value());
    EXPECT_LT(cost(*estimate, p, m), 1e-12);
    EXPECT_LT(rotation_difference_deg(*estimate, truth), 1e-9);
  }
  {
    // Collinear points: the spin about the line is free, but the pairs are still matched exactly.
    std::vector<Eigen::Vector3d> p, m;
    for (int i = 0; i < 30; ++i) {
      p.push_back(kFarReference + u(rng) * Eigen::Vector3d(0.6, 0.0, 0.8));
      m.push_back(apply(truth, p.back()));
    }
    const auto estimate = horn_transform(sums_from_pairs(p, m, kFarReference));
    ASSERT_TRUE(estimate.has_value());
    EXPECT_TRUE(is_valid_rigid(*estimate, 1e-12));
    EXPECT_LT(cost(*estimate, p, m), 1e-12);
  }
  {
    // Exactly three pairs are enough.
    std::vector<Eigen::Vector3d> p = {kFarReference, kFarReference + Eigen::Vector3d(100, 0, 0),
                                      kFarReference + Eigen::Vector3d(0, 50, 30)};
    std::vector<Eigen::Vector3d> m;
    for (const auto& x : p) m.push_back(apply(truth, x));
    const auto estimate = horn_transform(sums_from_pairs(p, m, kFarReference));
    ASSERT_TRUE(estimate.has_value());
    EXPECT_LT(rotation_difference_deg(*estimate, truth), 1e-9);
    EXPECT_LT(translation_difference_cm(*estimate, truth), 1e-7);
  }
}

TEST(HornTransform, RejectsTooFewPairsAndNonFiniteSums) {
  const Pose truth = make_pose(axis_angle({0, 1, 0}, 0.3), {1, 2, 3});
  std::vector<Eigen::Vector3d> p = {{0, 0, 0}, {100, 0, 0}, {0, 100, 0}, {0, 0, 100}};
  std::vector<Eigen::Vector3d> m;
  for (const auto& x : p) m.push_back(apply(truth, x));
  for (int n : {0, 1, 2}) {
    const std::vector<Eigen::Vector3d> pn(p.begin(), p.begin() + n), mn(m.begin(), m.begin() + n);
    EXPECT_FALSE(horn_transform(sums_from_pairs(pn, mn, Eigen::Vector3d::Zero())).has_value()) << n << " pairs";
  }
  EXPECT_FALSE(horn_transform(PairSums{}).has_value());
  const PairSums good = sums_from_pairs(p, m, kFarReference);
  ASSERT_TRUE(horn_transform(good).has_value());
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  auto broken = [&](auto mutate) {
    PairSums s = good;
    mutate(s);
    return horn_transform(s);
  };
  EXPECT_FALSE(broken([&](PairSums& s) { s.sum_data_model(1, 2) = nan; }).has_value());
  EXPECT_FALSE(broken([&](PairSums& s) { s.sum_data_model(0, 0) = inf; }).has_value());
  EXPECT_FALSE(broken([&](PairSums& s) { s.sum_data.x() = nan; }).has_value());
  EXPECT_FALSE(broken([&](PairSums& s) { s.sum_model.z() = nan; }).has_value());
  EXPECT_FALSE(broken([&](PairSums& s) { s.sum_model.y() = -inf; }).has_value());
  EXPECT_FALSE(broken([&](PairSums& s) { s.count = nan; }).has_value());
  EXPECT_FALSE(broken([&](PairSums& s) { s.weight = nan; }).has_value());
  EXPECT_FALSE(broken([&](PairSums& s) { s.weight = inf; }).has_value());
  EXPECT_FALSE(broken([&](PairSums& s) { s.weight = 0.0; }).has_value());  // every pair weighs nothing
  EXPECT_FALSE(broken([&](PairSums& s) { s.reference_cm.y() = nan; }).has_value());
  EXPECT_FALSE(broken([&](PairSums& s) { s.count = 2.0; }).has_value());  // fewer than 3 pairs
}

// =============================================================================================
// ICP on a synthetic room with pillars

/// A room 1200 x 800 cm with a tilted roof, three pillars (two boxes, one cylinder) and a wedge,
/// sampled uniformly by area (fixed seed). Local (room) frame, y up.
std::vector<Eigen::Vector3f> room_with_pillars(std::size_t count, std::uint32_t seed) {
  struct Patch {  // parallelogram o + a u + b v
    Eigen::Vector3d o, u, v;
  };
  std::vector<Patch> patches;
  auto roof_y = [](double x, double z) { return 290.0 + 0.05 * x + 0.03 * z; };
  patches.push_back({{-600, 0, -400}, {1200, 0, 0}, {0, 0, 800}});                     // floor
  patches.push_back({{-600, roof_y(-600, -400), -400}, {1200, 60, 0}, {0, 24, 800}});  // roof
  patches.push_back({{-600, 0, -400}, {0, 0, 800}, {0, 300, 0}});                      // wall x-
  patches.push_back({{600, 0, -400}, {0, 0, 800}, {0, 300, 0}});                       // wall x+
  patches.push_back({{-600, 0, -400}, {1200, 0, 0}, {0, 300, 0}});                     // wall z-
  patches.push_back({{-600, 0, 400}, {1200, 0, 0}, {0, 300, 0}});                      // wall z+
  patches.push_back({{-500, 0, 250}, {200, 0, 0}, {0, 80, 120}});                      // wedge
  auto box = [&](double x0, double x1, double z0, double z1) {
    patches.push_back({{x0, 0, z0}, {x1 - x0, 0, 0}, {0, 280, 0}});
    patches.push_back({{x0, 0, z1}, {x1 - x0, 0, 0}, {0, 280, 0}});
    patches.push_back({{x0, 0, z0}, {0, 0, z1 - z0}, {0, 280, 0}});
    patches.push_back({{x1, 0, z0}, {0, 0, z1 - z0}, {0, 280, 0}});
  };
  box(-300, -240, -150, -90);
  box(150, 230, 100, 140);
  const Eigen::Vector3d cylinder(350, 0, -200);
  const double radius = 45.0, height = 280.0;
  std::vector<double> areas;
  for (const auto& p : patches) areas.push_back(p.u.cross(p.v).norm());
  areas.push_back(2 * std::numbers::pi * radius * height);
  std::mt19937 rng(seed);
  std::discrete_distribution<std::size_t> which(areas.begin(), areas.end());
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Eigen::Vector3f> points;
  while (points.size() < count) {
    const std::size_t k = which(rng);
    const double a = u01(rng), b = u01(rng);
    if (k < patches.size()) {
      points.push_back((patches[k].o + a * patches[k].u + b * patches[k].v).cast<float>());
    } else {
      const double phi = 2 * std::numbers::pi * a;
      points.push_back(
          (cylinder + Eigen::Vector3d(radius * std::cos(phi), height * b, radius * std::sin(phi))).cast<float>());
    }
  }
  return points;
}

std::vector<Eigen::Vector3f> transformed(const std::vector<Eigen::Vector3f>& points, const Pose& t) {
  std::vector<Eigen::Vector3f> out;
  out.reserve(points.size());
  for (const auto& p : points) out.push_back(apply(t, p.cast<double>()).cast<float>());
  return out;
}

/// Largest displacement of the data cloud's points between two poses (what a pose error means).
double max_displacement_cm(const Pose& a, const Pose& b, std::span<const Eigen::Vector3f> points) {
  double worst = 0.0;
  for (const auto& p : points)
    worst = std::max(worst, (apply(a, p.cast<double>()) - apply(b, p.cast<double>())).norm());
  return worst;
}

/// One normal per data point of the room problem: its cell's plane (SurfaceNormals, 1 m: the data
/// are a quarter of 12 000 points over the room), or zero.
std::vector<Eigen::Vector3f> room_normals(std::span<const Eigen::Vector3f> points) {
  const SurfaceNormals planes(points, 100.0f);
  std::vector<Eigen::Vector3f> normals;
  for (const auto& p : points) normals.push_back(planes.at(p) != nullptr ? *planes.at(p) : Eigen::Vector3f::Zero());
  return normals;
}

/// The registration problem: the model is the room (placed in the world far from the origin);
/// the data is a quarter of the model's points, seen from a second pose; ICP starts from the true
/// data pose disturbed by ~14 cm and 1.5 degrees.
struct RoomProblem {
  std::vector<Eigen::Vector3f> room;         // model, room frame
  std::vector<Eigen::Vector3f> data_points;  // data, data frame
  Pose world_from_model;
  Pose world_from_data_true;
  Pose world_from_data_initial;

  explicit RoomProblem(std::size_t model_count = 12000, std::size_t data_stride = 4) {
    room = room_with_pillars(model_count, 31);
    world_from_model = make_pose(axis_angle({0, 1, 0}, 30 * kDeg), {1e5, 200, 5e4});
    const Pose model_from_data = make_pose(axis_angle({0.1, 1, 0.05}, 10 * kDeg), {40, 5, -30});
    world_from_data_true = world_from_model * model_from_data;
    std::vector<Eigen::Vector3f> subset;
    for (std::size_t i = 0; i < room.size(); i += data_stride) subset.push_back(room[i]);
    data_points = transformed(subset, rigid_inverse(model_from_data));
    const Pose error = make_pose(axis_angle({0.3, 1.0, 0.2}, 1.5 * kDeg), {8, -5, 10});
    world_from_data_initial = world_from_data_true * error;
  }
};

IcpSettings icp_settings(SearchMethod method) {
  IcpSettings s;
  s.method = method;
  s.max_pair_dist_cm = 50.0f;
  s.termination.max_iterations = 200;
  return s;
}

class IcpRoomTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    problem_ = new RoomProblem();
    backend_ = make_cpu_backend().release();
    model_ = backend_->prepare(problem_->room, {});
    data_ = backend_->prepare(problem_->data_points, {});
  }
  static void TearDownTestSuite() {
    model_.reset();
    data_.reset();
    delete backend_;
    delete problem_;
  }
  static IcpResult run(SearchMethod method, const Pose& start) {
    const WorldModel m{model_.get(), problem_->world_from_model};
    return register_icp(*backend_, *data_, start, {&m, 1}, icp_settings(method));
  }
  static void expect_at_truth(const IcpResult& r, const std::string& what) {
    const Pose& truth = problem_->world_from_data_true;
    const double dt = translation_difference_cm(r.world_from_data, truth);
    const double dr = rotation_difference_deg(r.world_from_data, truth);
    const double moved = max_displacement_cm(r.world_from_data, truth, problem_->data_points);
    std::printf(
        "[ icp      ] %-12s %-10s approx %2d exact %2d pairs %zu rms %.2e cm | dt %.2e cm dR %.2e deg "
        "max point error %.2e cm\n",
        what.c_str(), to_string(r.stop), r.approximate_iterations, r.exact_iterations, r.pairs, r.rms_cm, dt, dr,
        moved);
    EXPECT_TRUE(r.converged()) << what << ": " << to_string(r.stop);
    EXPECT_TRUE(r.ok());
    EXPECT_LT(dt, 0.05) << what;
    EXPECT_LT(dr, 0.01) << what;
    EXPECT_LT(moved, 0.05) << what;
    EXPECT_EQ(r.pairs, problem_->data_points.size()) << what;  // every data point has its twin
    // The RMS of the last iteration's pairs, i.e. before its (sub-threshold) step was applied.
    EXPECT_LT(r.rms_cm, 0.05) << what;
    EXPECT_TRUE(is_valid_rigid(r.world_from_data, 1e-12)) << what;
  }

  static RoomProblem* problem_;
  static ComputeBackend* backend_;
  static std::shared_ptr<const PreparedCloud> model_;
  static std::shared_ptr<const PreparedCloud> data_;
};
RoomProblem* IcpRoomTest::problem_ = nullptr;
ComputeBackend* IcpRoomTest::backend_ = nullptr;
std::shared_ptr<const PreparedCloud> IcpRoomTest::model_;
std::shared_ptr<const PreparedCloud> IcpRoomTest::data_;

TEST_F(IcpRoomTest, ProblemIsAsDescribed) {
  const Pose error = rigid_inverse(problem_->world_from_data_true) * problem_->world_from_data_initial;
  EXPECT_NEAR(translation_norm(error), std::sqrt(64.0 + 25 + 100), 1e-9);
  EXPECT_NEAR(rotation_angle_deg(error), 1.5, 1e-9);
  EXPECT_EQ(problem_->data_points.size(), 3000u);
}

TEST_F(IcpRoomTest, ExactSearchConvergesToTheTruth) {
  const auto r = run(SearchMethod::kExact, problem_->world_from_data_initial);
  expect_at_truth(r, "kd");
  EXPECT_EQ(r.approximate_iterations, 0);
  EXPECT_GE(r.exact_iterations, 2);
}

TEST_F(IcpRoomTest, BruteForceConvergesToTheTruthWithTheSamePairsAsExact) {
  const auto brute = run(SearchMethod::kBruteForce, problem_->world_from_data_initial);
  expect_at_truth(brute, "brute");
  const auto exact = run(SearchMethod::kExact, problem_->world_from_data_initial);
  // Same pairs in every iteration -> same sums -> the same pose.
  EXPECT_EQ(brute.exact_iterations, exact.exact_iterations);
  EXPECT_EQ(brute.pairs, exact.pairs);
  EXPECT_LT((brute.world_from_data - exact.world_from_data).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT(max_displacement_cm(brute.world_from_data, exact.world_from_data, problem_->data_points), 1e-6);
}

TEST_F(IcpRoomTest, ApproximateScheduleThenExactConvergesToTheTruth) {
  const auto r = run(SearchMethod::kApproximate, problem_->world_from_data_initial);
  expect_at_truth(r, "apx->kd");
  EXPECT_GT(r.approximate_iterations, 0);
  EXPECT_GE(r.exact_iterations, 1);
  EXPECT_EQ(r.iterations(), r.approximate_iterations + r.exact_iterations);
}

TEST_F(IcpRoomTest, StartingAtTheTruthStaysThere) {
  const auto r = run(SearchMethod::kExact, problem_->world_from_data_true);
  expect_at_truth(r, "from truth");
  EXPECT_LE(r.exact_iterations, 2);
}

TEST_F(IcpRoomTest, IterationCapStopsWithThePoseSoFar) {
  const WorldModel m{model_.get(), problem_->world_from_model};
  auto settings = icp_settings(SearchMethod::kExact);
  settings.termination.max_iterations = 3;
  const auto r = register_icp(*backend_, *data_, problem_->world_from_data_initial, {&m, 1}, settings);
  EXPECT_EQ(r.stop, IcpStop::kMaxIterations);
  EXPECT_TRUE(r.ok());
  EXPECT_FALSE(r.converged());
  EXPECT_EQ(r.iterations(), 3);
  // Three iterations moved toward the truth.
  const double before = translation_difference_cm(problem_->world_from_data_initial, problem_->world_from_data_true);
  EXPECT_LT(translation_difference_cm(r.world_from_data, problem_->world_from_data_true), before);
  EXPECT_TRUE(is_valid_rigid(r.world_from_data, 1e-12));
}

TEST_F(IcpRoomTest, NoOverlapFailsAndKeepsTheInitialPose) {
  const Pose far_model = make_pose(Eigen::Matrix3d::Identity(), {1e5, 0, 0}) * problem_->world_from_model;
  const WorldModel m{model_.get(), far_model};
  for (auto method : {SearchMethod::kExact, SearchMethod::kApproximate, SearchMethod::kBruteForce}) {
    const auto r = register_icp(*backend_, *data_, problem_->world_from_data_initial, {&m, 1}, icp_settings(method));
    EXPECT_EQ(r.stop, IcpStop::kTooFewPairs) << to_string(method);
    EXPECT_FALSE(r.ok());
    EXPECT_EQ(r.pairs, 0u);
    EXPECT_EQ(r.iterations(), 0);
    EXPECT_TRUE(r.world_from_data == problem_->world_from_data_initial) << "pose must be the initial one, bit for bit";
  }
  // No models at all: the same failure.
  const auto none =
      register_icp(*backend_, *data_, problem_->world_from_data_initial, {}, icp_settings(SearchMethod::kExact));
  EXPECT_EQ(none.stop, IcpStop::kTooFewPairs);
  EXPECT_TRUE(none.world_from_data == problem_->world_from_data_initial);
}

TEST_F(IcpRoomTest, TooFewPairsIsThePapersOverlapTest) {
  // 200 data points overlap perfectly, but the paper requires more than 250 pairs.
  std::vector<Eigen::Vector3f> few(problem_->data_points.begin(), problem_->data_points.begin() + 200);
  auto data = backend_->prepare(few, {});
  const WorldModel m{model_.get(), problem_->world_from_model};
  auto settings = icp_settings(SearchMethod::kExact);
  const auto r = register_icp(*backend_, *data, problem_->world_from_data_initial, {&m, 1}, settings);
  EXPECT_EQ(r.stop, IcpStop::kTooFewPairs);
  EXPECT_TRUE(r.world_from_data == problem_->world_from_data_initial);
  EXPECT_GT(r.pairs, 100u);  // pairs were found, just not enough
  settings.termination.min_pairs = 100;
  const auto relaxed = register_icp(*backend_, *data, problem_->world_from_data_initial, {&m, 1}, settings);
  EXPECT_TRUE(relaxed.ok()) << to_string(relaxed.stop);
}

TEST_F(IcpRoomTest, CountPairsMatchesBruteForce) {
  const WorldModel m{model_.get(), problem_->world_from_model};
  std::vector<Eigen::Vector3d> model_world;
  for (const auto& p : problem_->room) model_world.push_back(apply(problem_->world_from_model, p.cast<double>()));
  for (double bound : {5.0, 25.0}) {
    const Pose& pose = problem_->world_from_data_initial;
    std::size_t expected = 0, borderline = 0;
    for (const auto& p : problem_->data_points) {
      const Eigen::Vector3d q = apply(pose, p.cast<double>());
      double best = std::numeric_limits<double>::infinity();
      for (const auto& w : model_world) best = std::min(best, (w - q).squaredNorm());
      const double d = std::sqrt(best);
      if (std::abs(d - bound) < 1e-3) ++borderline;
      if (d < bound) ++expected;
    }
    const auto counted = count_pairs(*backend_, *data_, pose, m, static_cast<float>(bound));
    EXPECT_LE(std::max(counted, expected) - std::min(counted, expected), borderline) << "bound " << bound;
    EXPECT_GT(counted, 100u);
  }
  EXPECT_EQ(count_pairs(*backend_, *data_, problem_->world_from_data_true, m, 25.0f), problem_->data_points.size());
}

TEST_F(IcpRoomTest, UnionOfTwoModelsEqualsTheWholeModel) {
  // Split the room at x = 0 into two models, each stored in its own frame (as two scans are).
  std::vector<Eigen::Vector3f> left, right;
  for (const auto& p : problem_->room) (p.x() < 0 ? left : right).push_back(p);
  const Pose frame_left = make_pose(axis_angle({1, 0, 0}, 5 * kDeg), {-300, 0, 20});
  const Pose frame_right = make_pose(axis_angle({0, 0, 1}, -7 * kDeg), {250, 10, -40});
  auto model_left = backend_->prepare(transformed(left, rigid_inverse(frame_left)), {});
  auto model_right = backend_->prepare(transformed(right, rigid_inverse(frame_right)), {});
  const std::vector<WorldModel> both = {{model_left.get(), problem_->world_from_model * frame_left},
                                        {model_right.get(), problem_->world_from_model * frame_right}};
  const auto whole = run(SearchMethod::kExact, problem_->world_from_data_initial);
  const auto split =
      register_icp(*backend_, *data_, problem_->world_from_data_initial, both, icp_settings(SearchMethod::kExact));
  expect_at_truth(split, "two models");
  const double difference = max_displacement_cm(whole.world_from_data, split.world_from_data, problem_->data_points);
  std::printf("[ icp      ] union of two models vs whole model: max point difference %.2e cm\n", difference);
  EXPECT_LT(difference, 1e-4);
  EXPECT_EQ(split.pairs, whole.pairs);
}

TEST_F(IcpRoomTest, DeterministicRunToRunAndAcrossThreadCounts) {
  for (auto method : {SearchMethod::kExact, SearchMethod::kApproximate}) {
    const auto first = run(method, problem_->world_from_data_initial);
    const auto second = run(method, problem_->world_from_data_initial);
    EXPECT_TRUE(first.world_from_data == second.world_from_data) << to_string(method);
    EXPECT_EQ(first.rms_cm, second.rms_cm);
    IcpResult one_thread, two_threads;
    tbb::task_arena(1).execute([&] { one_thread = run(method, problem_->world_from_data_initial); });
    tbb::task_arena(2).execute([&] { two_threads = run(method, problem_->world_from_data_initial); });
    EXPECT_TRUE(one_thread.world_from_data == two_threads.world_from_data) << to_string(method);
    EXPECT_TRUE(one_thread.world_from_data == first.world_from_data) << to_string(method);
    EXPECT_EQ(one_thread.rms_cm, two_threads.rms_cm);
    EXPECT_EQ(one_thread.iterations(), two_threads.iterations());
  }
}

/// Forwards to a backend and records every pairing call: which search, and the RMS it found.
/// Forwards every call to another backend; test decorators override what they observe or break.
class ForwardingBackend : public ComputeBackend {
 public:
  explicit ForwardingBackend(ComputeBackend& inner) : inner_(inner) {}
  std::string name() const override { return inner_.name(); }
  std::string device_description() const override { return inner_.device_description(); }
  std::shared_ptr<const PreparedCloud> prepare(std::vector<Eigen::Vector3f> points, const KdTreeSettings& settings,
                                               TreeBuild when = TreeBuild::kNow) override {
    return inner_.prepare(std::move(points), settings, when);
  }
  PairSums pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                        const PairingSettings& settings) override {
    return inner_.pair_and_sum(data, models, method, settings);
  }
  std::vector<NearestPair> nearest(const PreparedCloud& data, std::span<const ModelPlacement> models,
                                   SearchMethod method, const PairingSettings& settings) override {
    return inner_.nearest(data, models, method, settings);
  }

 protected:
  SliceFilterResult filter_slices_checked(const Scan& scan, const SliceFilterSettings& settings) override {
    return inner_.filter_slices(scan, settings);
  }

 private:
  ComputeBackend& inner_;
};

class RecordingBackend final : public ForwardingBackend {
 public:
  struct Call {
    SearchMethod method;
    double rms_cm;
    double pairs;
    float max_pair_dist_cm;
  };
  using ForwardingBackend::ForwardingBackend;
  PairSums pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                        const PairingSettings& settings) override {
    PairSums sums = ForwardingBackend::pair_and_sum(data, models, method, settings);
    calls.push_back({method, sums.rms_cm(), sums.count, settings.max_pair_dist_cm});
    return sums;
  }
  std::vector<Call> calls;
};

TEST_F(IcpRoomTest, ScheduleIsApproximateWhileTheErrorFallsThenExact) {
  const WorldModel m{model_.get(), problem_->world_from_model};
  {
    RecordingBackend recorder(*backend_);
    const auto r = register_icp(recorder, *data_, problem_->world_from_data_initial, {&m, 1},
                                icp_settings(SearchMethod::kApproximate));
    ASSERT_TRUE(r.converged());
    const auto& calls = recorder.calls;
    std::size_t apx = 0;
    while (apx < calls.size() && calls[apx].method == SearchMethod::kApproximate) ++apx;
    for (std::size_t i = apx; i < calls.size(); ++i) {
      EXPECT_EQ(calls[i].method, SearchMethod::kExact) << "call " << i << ": never back to approximate";
    }
    for (const auto& c : calls) EXPECT_EQ(c.max_pair_dist_cm, 50.0f);
    const auto used = static_cast<std::size_t>(r.approximate_iterations);
    ASSERT_GE(used, 2u);
    // The error fell in every approximate iteration that was used...
    for (std::size_t i = 1; i < used; ++i) EXPECT_LT(calls[i].rms_cm, calls[i - 1].rms_cm) << "approximate call " << i;
    // ...and the switch came either with an approximate pass whose error did not fall (discarded
    // and redone with exact pairs) or after an approximate step below the thresholds.
    if (apx == used + 1) {
      EXPECT_GE(calls[apx - 1].rms_cm, calls[apx - 2].rms_cm) << "an approximate pass was discarded though it improved";
    } else {
      EXPECT_EQ(apx, used);
    }
    EXPECT_EQ(calls.size() - apx, static_cast<std::size_t>(r.exact_iterations));
    EXPECT_GE(r.exact_iterations, 1);
    EXPECT_LE(r.exact_iterations, 5);  // the paper: usually 1-3 exact iterations finish the job
    // The result's figures are those of the last pairing.
    EXPECT_EQ(r.rms_cm, calls.back().rms_cm);
    EXPECT_EQ(static_cast<double>(r.pairs), calls.back().pairs);
  }
  for (auto method : {SearchMethod::kExact, SearchMethod::kBruteForce}) {
    RecordingBackend recorder(*backend_);
    const auto r = register_icp(recorder, *data_, problem_->world_from_data_initial, {&m, 1}, icp_settings(method));
    ASSERT_TRUE(r.converged());
    EXPECT_EQ(recorder.calls.size(), static_cast<std::size_t>(r.exact_iterations));
    EXPECT_EQ(r.approximate_iterations, 0);
    for (const auto& c : recorder.calls) EXPECT_EQ(c.method, method);
  }
}

TEST_F(IcpRoomTest, ApproximatePhaseThatSettlesIsStillFinishedWithExactSearch) {
  // Coarse step thresholds make the approximate phase end by a small step (not by a rising
  // error): the schedule must still switch to exact search before declaring convergence.
  const WorldModel m{model_.get(), problem_->world_from_model};
  auto settings = icp_settings(SearchMethod::kApproximate);
  settings.termination.min_translation_step_cm = 3.0;
  settings.termination.min_rotation_step_deg = 0.5;
  RecordingBackend recorder(*backend_);
  const auto r = register_icp(recorder, *data_, problem_->world_from_data_initial, {&m, 1}, settings);
  EXPECT_TRUE(r.converged()) << to_string(r.stop);
  EXPECT_GE(r.approximate_iterations, 1);
  EXPECT_GE(r.exact_iterations, 1);
  ASSERT_FALSE(recorder.calls.empty());
  EXPECT_EQ(recorder.calls.back().method, SearchMethod::kExact);
  // Every approximate pass was used (none discarded): the phase ended by settling.
  std::size_t apx = 0;
  for (const auto& c : recorder.calls) apx += c.method == SearchMethod::kApproximate;
  EXPECT_EQ(apx, static_cast<std::size_t>(r.approximate_iterations));
}

/// Forwards to a backend, but from pairing call `from_call` on returns broken sums.
class FaultyBackend final : public ForwardingBackend {
 public:
  enum class Fault { kNaN, kNoPairs };
  FaultyBackend(ComputeBackend& inner, int from_call, Fault fault)
      : ForwardingBackend(inner), from_(from_call), fault_(fault) {}
  std::string name() const override { return "faulty"; }
  std::string device_description() const override { return "faulty"; }
  PairSums pair_and_sum(const PreparedCloud& data, std::span<const ModelPlacement> models, SearchMethod method,
                        const PairingSettings& settings) override {
    PairSums sums = ForwardingBackend::pair_and_sum(data, models, method, settings);
    if (calls_++ >= from_) {
      if (fault_ == Fault::kNaN) {
        sums.sum_data_model(0, 1) = std::numeric_limits<double>::quiet_NaN();
      } else {
        sums = PairSums{};
        sums.count = 7;
      }
    }
    return sums;
  }

 private:
  int calls_ = 0;
  int from_;
  Fault fault_;
};

TEST_F(IcpRoomTest, FailureInAnyIterationReturnsTheInitialPose) {
  const WorldModel m{model_.get(), problem_->world_from_model};
  for (auto fault : {FaultyBackend::Fault::kNaN, FaultyBackend::Fault::kNoPairs}) {
    for (int from : {0, 3}) {
      FaultyBackend faulty(*backend_, from, fault);
      const auto r =
          register_icp(faulty, *data_, problem_->world_from_data_initial, {&m, 1}, icp_settings(SearchMethod::kExact));
      const auto expected = fault == FaultyBackend::Fault::kNaN ? IcpStop::kNumericFailure : IcpStop::kTooFewPairs;
      EXPECT_EQ(r.stop, expected) << "fault from call " << from;
      EXPECT_FALSE(r.ok());
      EXPECT_TRUE(r.world_from_data == problem_->world_from_data_initial) << "fault from call " << from;
      EXPECT_EQ(r.exact_iterations, from);  // the iterations completed before the failure
      if (fault == FaultyBackend::Fault::kNoPairs) {
        EXPECT_EQ(r.pairs, 7u);
      }
    }
  }
}

// =============================================================================================
// CPU vs OpenCL

TEST(IcpBackends, CpuAndOpenClAgree) {
  const RoomProblem problem;
  auto cpu = make_cpu_backend();
  auto device = test::opencl_backend();  // throws (test fails) without OpenCL
  ASSERT_NE(device, nullptr);
  EXPECT_EQ(device->name(), "opencl");
  auto cpu_model = cpu->prepare(problem.room, {});
  auto cpu_data = cpu->prepare(problem.data_points, {});
  auto dev_model = device->prepare(problem.room, {});
  auto dev_data = device->prepare(problem.data_points, {});
  for (auto method : {SearchMethod::kExact, SearchMethod::kApproximate}) {
    const WorldModel mc{cpu_model.get(), problem.world_from_model};
    const WorldModel md{dev_model.get(), problem.world_from_model};
    const auto a = register_icp(*cpu, *cpu_data, problem.world_from_data_initial, {&mc, 1}, icp_settings(method));
    const auto b = register_icp(*device, *dev_data, problem.world_from_data_initial, {&md, 1}, icp_settings(method));
    const double dt = translation_difference_cm(a.world_from_data, b.world_from_data);
    const double dr = rotation_difference_deg(a.world_from_data, b.world_from_data);
    const double dp = max_displacement_cm(a.world_from_data, b.world_from_data, problem.data_points);
    std::printf(
        "[ backends ] %-5s cpu: %s apx %d exact %d rms %.3e | opencl: %s apx %d exact %d rms %.3e | "
        "dt %.2e cm dR %.2e deg max point %.2e cm\n",
        to_string(method), to_string(a.stop), a.approximate_iterations, a.exact_iterations, a.rms_cm, to_string(b.stop),
        b.approximate_iterations, b.exact_iterations, b.rms_cm, dt, dr, dp);
    EXPECT_TRUE(a.converged());
    EXPECT_TRUE(b.converged());
    EXPECT_LT(dt, 0.01) << to_string(method);
    EXPECT_LT(dr, 0.001) << to_string(method);
    EXPECT_EQ(a.approximate_iterations, b.approximate_iterations) << to_string(method);
    EXPECT_EQ(a.exact_iterations, b.exact_iterations) << to_string(method);
    EXPECT_EQ(a.pairs, b.pairs) << to_string(method);
    // Both at the truth.
    EXPECT_LT(max_displacement_cm(b.world_from_data, problem.world_from_data_true, problem.data_points), 0.05);
    // Point-to-plane: the device pairs, the host sums (ComputeBackend::pair_and_plane_sum), the CPU
    // sums as it searches: the same poses, bit for bit.
    IcpSettings planes = icp_settings(method);
    planes.objective = IcpObjective::kPointToPlane;
    const std::vector<Eigen::Vector3f> normals = room_normals(problem.data_points);
    const auto pa = register_icp(*cpu, *cpu_data, problem.world_from_data_initial, {&mc, 1}, planes, normals);
    const auto pb = register_icp(*device, *dev_data, problem.world_from_data_initial, {&md, 1}, planes, normals);
    EXPECT_TRUE(pa.converged()) << to_string(method);
    EXPECT_TRUE(pa.world_from_data == pb.world_from_data) << to_string(method);
    EXPECT_EQ(pa.iterations(), pb.iterations()) << to_string(method);
    // The device run is deterministic too.
    const auto c = register_icp(*device, *dev_data, problem.world_from_data_initial, {&md, 1}, icp_settings(method));
    EXPECT_TRUE(c.world_from_data == b.world_from_data) << to_string(method);
  }
}

// Point-to-plane ICP on the data's own planes (IcpObjective::kPointToPlane) lands on the truth as
// the paper's does, from the same start; without one normal per data point it refuses to run.
TEST_F(IcpRoomTest, PointToPlaneOnTheDatasPlanesConvergesToTheTruth) {
  const std::vector<Eigen::Vector3f> normals = room_normals(problem_->data_points);
  std::size_t on_planes = 0;
  for (const auto& n : normals) on_planes += n.squaredNorm() > 0.0f ? 1 : 0;
  EXPECT_GT(on_planes, normals.size() / 2);
  EXPECT_LT(on_planes, normals.size());  // edges and the pillar's curve: point-to-point terms too
  const WorldModel m{model_.get(), problem_->world_from_model};
  for (const SearchMethod method : {SearchMethod::kExact, SearchMethod::kApproximate}) {
    IcpSettings planes = icp_settings(method);
    planes.objective = IcpObjective::kPointToPlane;
    const IcpResult r = register_icp(*backend_, *data_, problem_->world_from_data_initial, {&m, 1}, planes, normals);
    expect_at_truth(r, std::string("plane ") + to_string(method));
    EXPECT_THROW(register_icp(*backend_, *data_, problem_->world_from_data_initial, {&m, 1}, planes),
                 std::invalid_argument);
  }
}

TEST_F(IcpRoomTest, AccelerationKeepsTheTruth) {
  const WorldModel m{model_.get(), problem_->world_from_model};
  for (auto method : {SearchMethod::kExact, SearchMethod::kApproximate}) {
    auto settings = icp_settings(method);
    const auto plain = register_icp(*backend_, *data_, problem_->world_from_data_initial, {&m, 1}, settings);
    settings.accelerate = true;
    const auto accelerated = register_icp(*backend_, *data_, problem_->world_from_data_initial, {&m, 1}, settings);
    expect_at_truth(accelerated, std::string("accelerated ") + to_string(method));
    // Plain ICP needs few steps here (exact twins): acceleration has little to extrapolate, and a
    // guess that does not lower the objective costs one pairing. Its gain is on creeping problems.
    EXPECT_LE(accelerated.iterations(), plain.iterations() + 3) << to_string(method);
    EXPECT_EQ(accelerated.approximate_iterations, plain.approximate_iterations) << "only exact steps are accelerated";
  }
}

// A paper-size pair of the simulated mine, reduced by the slice filter: exact point-to-point ICP
// creeps here (each step ~0.85 of the one before, mostly a rotation about the drive direction),
// which is what Anderson acceleration is for.
TEST(IcpAcceleration, MinePairReachesThePlainResultInFewerIterationsOnBothBackends) {
  sim::SimulationSettings simulation;
  simulation.mine.scans = 2;
  simulation.mine.seed = 1;
  const auto survey = sim::simulate_mine_survey(simulation);
  auto cpu = make_cpu_backend();
  auto device = test::opencl_backend();  // throws (test fails) without OpenCL
  const auto model_points = filter_scan_cpu(survey.scans[0], {}).points_cm;
  const auto data_points = filter_scan_cpu(survey.scans[1], {}).points_cm;
  const auto model = cpu->prepare(model_points, {});
  const auto data = cpu->prepare(data_points, {});
  const WorldModel placed{model.get(), survey.truth_cm[0]};
  const Pose start = survey.truth_cm[0] * rigid_inverse(survey.scans[0].pose_cm) * survey.scans[1].pose_cm;

  // Where plain ICP ends when it is not stopped early (it may cycle between pair sets at the end:
  // the iteration cap is the stop then).
  IcpSettings settings;
  settings.method = SearchMethod::kExact;
  IcpSettings tight = settings;
  tight.termination.min_translation_step_cm = 1e-5;
  tight.termination.min_rotation_step_deg = 1e-6;
  tight.termination.max_iterations = 400;
  const auto reference = register_icp(*cpu, *data, start, {&placed, 1}, tight);
  ASSERT_TRUE(reference.ok());

  for (auto method : {SearchMethod::kExact, SearchMethod::kApproximate}) {
    settings.method = method;
    settings.accelerate = false;
    const auto plain = register_icp(*cpu, *data, start, {&placed, 1}, settings);
    settings.accelerate = true;
    const auto accelerated = register_icp(*cpu, *data, start, {&placed, 1}, settings);
    std::printf("[ accel    ] %-5s plain %d + %d iterations, accelerated %d + %d (%d jumps kept, %d taken back)\n",
                to_string(method), plain.approximate_iterations, plain.exact_iterations,
                accelerated.approximate_iterations, accelerated.exact_iterations, accelerated.accelerations,
                accelerated.rejected_accelerations);
    ASSERT_TRUE(plain.converged());
    ASSERT_TRUE(accelerated.converged());
    EXPECT_GT(accelerated.accelerations, 0);
    EXPECT_LT(accelerated.iterations(), plain.iterations()) << to_string(method);
    // The valley's floor is flat to a few mm (plain ICP's own stopping point lies that far from the
    // reference too): both stop within the same distance of it.
    for (const auto* result : {&plain, &accelerated}) {
      EXPECT_LT(translation_difference_cm(result->world_from_data, reference.world_from_data), 0.5) << to_string(method);
      EXPECT_LT(rotation_difference_deg(result->world_from_data, reference.world_from_data), 0.05) << to_string(method);
    }
    // Acceleration runs on the host from the backend's sums, which are bit-identical: so are the poses.
    const auto device_model = device->prepare(model_points, {});
    const auto device_data = device->prepare(data_points, {});
    const WorldModel device_placed{device_model.get(), survey.truth_cm[0]};
    const auto on_device = register_icp(*device, *device_data, start, {&device_placed, 1}, settings);
    EXPECT_TRUE(on_device.world_from_data == accelerated.world_from_data) << to_string(method);
    EXPECT_EQ(on_device.exact_iterations, accelerated.exact_iterations);
  }
}

// =============================================================================================
// The spring to the start (IcpSettings::start_spring_pairs)

/// The weight measured on the simulated sequences (docs/benchmarks.md, "A spring to the prediction").
constexpr float kSpringPairs = 160.0f;

/// A straight corridor along x, 400 cm wide and 300 cm high (floor, roof, two walls), its points
/// uniform by area from x_from to x_to cm (fixed seed): surfaces that pin everything but the axis.
std::vector<Eigen::Vector3f> corridor(double x_from, double x_to, std::size_t count, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Eigen::Vector3f> points;
  for (std::size_t k = 0; k < count; ++k) {
    const double x = x_from + (x_to - x_from) * u01(rng), a = u01(rng);
    // Floor and roof 400 cm across, walls 300 cm high: by area, 4 : 4 : 3 : 3.
    const double side = 14.0 * u01(rng);
    if (side < 4.0) points.emplace_back(x, -200.0 + 400.0 * a, 0.0);
    else if (side < 8.0) points.emplace_back(x, -200.0 + 400.0 * a, 300.0);
    else if (side < 11.0) points.emplace_back(x, -200.0, 300.0 * a);
    else points.emplace_back(x, 200.0, 300.0 * a);
  }
  return points;
}

/// The sensor sees 1 m past the end of the map it is matched against (the model ends at x = 1000
/// cm, the data at 1100), as a moving sensor's sweep sees past its local map: the points beyond
/// the end pair with the end's within the bound and pull the match back along the corridor, which
/// no surface pins. Started at the truth along it, the paper's ICP slides back most of a metre;
/// the spring holds it within a tenth of that, while the walls still pull the match across the
/// corridor most of the way from a start off there (the spring's share is its weight against the
/// wall points', about a fifth).
TEST(IcpStartSpring, HoldsTheStartAlongWhatTheSurfacesDoNotPin) {
  const auto backend = make_cpu_backend();
  const auto model = backend->prepare(corridor(-1000.0, 1000.0, 12000, 5), {});
  const auto data = backend->prepare(corridor(-900.0, 1100.0, 3000, 6), {});
  const WorldModel m{model.get(), Pose::Identity()};
  IcpSettings settings = icp_settings(SearchMethod::kExact);
  const Pose start = make_pose(axis_angle({0, 0, 1}, 0.5 * kDeg), {0.0, 8.0, -5.0});  // off across, turned
  const IcpResult plain = register_icp(*backend, *data, start, {&m, 1}, settings);
  settings.start_spring_pairs = kSpringPairs;
  const IcpResult held = register_icp(*backend, *data, start, {&m, 1}, settings);
  const Pose& p = plain.world_from_data;
  const Pose& h = held.world_from_data;
  std::printf("[ spring   ] along the corridor: plain %.2f cm, held %.2f cm; across %.2f / %.2f cm, up %.2f / %.2f cm, "
              "turned %.3f / %.3f deg\n",
              p(0, 3), h(0, 3), p(1, 3), h(1, 3), p(2, 3), h(2, 3), rotation_angle_deg(p), rotation_angle_deg(h));
  ASSERT_TRUE(plain.ok());
  ASSERT_TRUE(held.converged());
  EXPECT_LT(p(0, 3), -50.0) << "the geometry of the test: the paper's ICP slides back";
  EXPECT_LT(std::abs(h(0, 3)), 0.15 * std::abs(p(0, 3)));
  EXPECT_LT(std::abs(h(1, 3)), 0.3 * 8.0) << "across the corridor: the walls outweigh the spring";
  EXPECT_LT(std::abs(h(2, 3)), 0.3 * 5.0) << "floor and roof";
  EXPECT_LT(rotation_angle_deg(h), 0.5);
}

/// Where every direction is pinned, the spring moves the match from the truth by about its share
/// of the weight (160 of 3 160 pairs against a start 14 cm off): less than a centimetre. With no
/// weight it is the paper's ICP, bit for bit.
TEST_F(IcpRoomTest, AStartSpringMovesAPinnedMatchByItsShareOfTheWeight) {
  const WorldModel m{model_.get(), problem_->world_from_model};
  IcpSettings settings = icp_settings(SearchMethod::kExact);
  const IcpResult plain = register_icp(*backend_, *data_, problem_->world_from_data_initial, {&m, 1}, settings);
  settings.start_spring_pairs = 0.0f;
  const IcpResult none = register_icp(*backend_, *data_, problem_->world_from_data_initial, {&m, 1}, settings);
  EXPECT_TRUE(none.world_from_data == plain.world_from_data);
  settings.start_spring_pairs = kSpringPairs;
  const IcpResult held = register_icp(*backend_, *data_, problem_->world_from_data_initial, {&m, 1}, settings);
  ASSERT_TRUE(held.converged());
  const Pose& truth = problem_->world_from_data_true;
  const double off_cm = translation_difference_cm(held.world_from_data, truth);
  std::printf("[ spring   ] pinned room: %.3f cm, %.4f deg from the truth (start %.1f cm off)\n", off_cm,
              rotation_difference_deg(held.world_from_data, truth),
              translation_difference_cm(problem_->world_from_data_initial, truth));
  EXPECT_GT(off_cm, 0.05) << "the spring pulls";
  EXPECT_LT(off_cm, 1.0);
  EXPECT_LT(rotation_difference_deg(held.world_from_data, truth), 0.05);
}

}  // namespace
}  // namespace minemap
