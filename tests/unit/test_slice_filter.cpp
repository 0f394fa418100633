// The slice filter (paper, section IV.C): median filter against salt-and-pepper noise, reduction of
// consecutive close points, every-third-slice selection. Every input is run through BOTH backends
// (CPU reference and the OpenCL kernel, on PoCL in CI) and the outputs must agree bit for bit: the
// two compute in float in the same order with contraction off and correctly rounded div/sqrt.
// The checks themselves use independent oracles in double: a brute-force median, and a search for
// the contiguous partition of the input whose means are the output points.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "minemap/backend/cpu_backend.hpp"
#include "minemap/backend/make_backend.hpp"
#include "minemap/filter/slice_filter.hpp"
#include "minemap/sim/mine_simulator.hpp"
#include "minemap/slam/survey_matching.hpp"
#include "test_support.hpp"

namespace minemap {
namespace {

using Slice = std::vector<Eigen::Vector3f>;

// ---------------------------------------------------------------------------------------------
// Scan construction

Scan make_scan(const std::vector<Slice>& slices, const std::string& name = "synthetic") {
  Scan scan;
  scan.name = name;
  scan.slice_offsets.push_back(0);
  for (const auto& s : slices) {
    scan.points_cm.insert(scan.points_cm.end(), s.begin(), s.end());
    scan.slice_offsets.push_back(static_cast<std::uint32_t>(scan.points_cm.size()));
  }
  return scan;
}

/// A point at `range` along beam angle `angle_rad` of a slice tilted by `tilt_rad` about the x axis.
Eigen::Vector3f beam_point(double range, double angle_rad, double tilt_rad) {
  const Eigen::Vector3d d(std::cos(angle_rad), std::sin(angle_rad) * std::cos(tilt_rad),
                          std::sin(angle_rad) * std::sin(tilt_rad));
  return (range * d).cast<float>();
}

double range_of(const Eigen::Vector3f& p) { return p.cast<double>().norm(); }

/// Scales a point along its beam to a new range (the scanner's salt-and-pepper: a wrong range).
Eigen::Vector3f at_range(const Eigen::Vector3f& p, double range) {
  return (p.cast<double>() * (range / range_of(p))).cast<float>();
}

// ---------------------------------------------------------------------------------------------
// Running both backends and comparing bit for bit

std::uint32_t bits(float f) { return std::bit_cast<std::uint32_t>(f); }

struct AgreementLog {
  std::size_t inputs = 0;
  std::size_t points_compared = 0;
  std::size_t bitwise_differences = 0;
  double max_abs_difference_cm = 0.0;
};
AgreementLog& agreement() {
  static AgreementLog log;
  return log;
}

/// The OpenCL backend, made once. No OpenCL device is a failure of the test, never a skip
/// (OPENCL.md section 3.5): test::opencl_backend throws.
ComputeBackend& opencl() {
  static const std::unique_ptr<ComputeBackend> backend = test::opencl_backend();
  return *backend;
}

SliceFilterResult run_opencl(const Scan& scan, const SliceFilterSettings& settings) {
  return opencl().filter_slices(scan, settings);
}

/// Runs the CPU reference and the OpenCL kernel, requires identical bits, returns the CPU result.
SliceFilterResult filter_both(const Scan& scan, const SliceFilterSettings& settings) {
  SliceFilterResult cpu = filter_scan_cpu(scan, settings);
  const SliceFilterResult gpu = run_opencl(scan, settings);
  EXPECT_EQ(cpu.backend, "cpu");
  EXPECT_EQ(gpu.backend, "opencl");
  EXPECT_EQ(cpu.points_in, gpu.points_in);
  EXPECT_EQ(cpu.points_in_kept_slices, gpu.points_in_kept_slices);
  EXPECT_EQ(cpu.outliers_replaced, gpu.outliers_replaced);
  EXPECT_EQ(cpu.slice_offsets, gpu.slice_offsets) << "scan " << scan.name;
  EXPECT_EQ(cpu.points_cm.size(), gpu.points_cm.size()) << "scan " << scan.name;
  auto& log = agreement();
  ++log.inputs;
  std::size_t reported = 0;
  for (std::size_t i = 0; i < std::min(cpu.points_cm.size(), gpu.points_cm.size()); ++i) {
    ++log.points_compared;
    for (int d = 0; d < 3; ++d) {
      const float a = cpu.points_cm[i][d], b = gpu.points_cm[i][d];
      if (bits(a) != bits(b)) {
        ++log.bitwise_differences;
        log.max_abs_difference_cm = std::max(log.max_abs_difference_cm, std::abs(double(a) - double(b)));
        if (reported++ < 5) {
          ADD_FAILURE() << "scan " << scan.name << ": point " << i << " axis " << d << " differs: cpu " << a << " (0x"
                        << std::hex << bits(a) << ") vs opencl " << b << " (0x" << bits(b) << std::dec << ")";
        }
      }
    }
  }
  return cpu;
}

// ---------------------------------------------------------------------------------------------
// Oracles (double precision, written independently of the implementation)

/// Brute-force median filter of one slice, compared with the filter's output `out`: for each
/// point, the lower median (by range, ties by index) of the window of `window` points centred on
/// it (clipped at the slice ends) replaces it iff the ranges differ by more than the threshold.
/// Ranges are computed in double; where two window ranges are equal to float resolution the
/// implementation (which sorts float squared ranges) may pick either, so any point of the window
/// whose range ties the median's is accepted. Returns the indices the oracle replaces.
std::vector<int> expect_median_filtered(const Slice& in, std::span<const Eigen::Vector3f> out, int window,
                                        double threshold, const std::string& where) {
  const int n = static_cast<int>(in.size());
  const int half = window / 2;
  std::vector<int> replaced;
  EXPECT_EQ(out.size(), in.size()) << where;
  if (out.size() != in.size()) return replaced;
  int failures = 0;
  for (int i = 0; i < n; ++i) {
    std::vector<std::pair<double, int>> w;
    for (int j = std::max(0, i - half); j <= std::min(n - 1, i + half); ++j) w.emplace_back(range_of(in[j]), j);
    std::sort(w.begin(), w.end());
    const auto median = w[(w.size() - 1) / 2];
    const double difference = std::abs(range_of(in[i]) - median.first);
    EXPECT_GT(std::abs(difference - threshold), 1e-3 + 1e-6 * median.first) << where << ": test data on the threshold";
    const bool replace = difference > threshold;
    bool ok = false;
    if (!replace) {
      ok = bits(out[i].x()) == bits(in[i].x()) && bits(out[i].y()) == bits(in[i].y()) &&
           bits(out[i].z()) == bits(in[i].z());
    } else {
      replaced.push_back(i);
      for (const auto& [r, j] : w) {
        const bool tie = std::abs(r - median.first) <= 1e-6 * (1.0 + median.first);
        ok |= tie && bits(out[i].x()) == bits(in[j].x()) && bits(out[i].y()) == bits(in[j].y()) &&
              bits(out[i].z()) == bits(in[j].z());
      }
    }
    if (!ok && failures++ < 5) {
      ADD_FAILURE() << where << ": point " << i << (replace ? " should be replaced by point " : " should stay ")
                    << (replace ? median.second : i) << " (" << in[replace ? median.second : i].transpose()
                    << "), got (" << out[i].transpose() << ")";
    }
  }
  return replaced;
}

/// Searches for a partition of `in` into contiguous runs whose double means equal `out` (in
/// order) within `tolerance`. Returns the run lengths, or an empty vector when no partition fits.
std::vector<int> partition_into_means(const Slice& in, std::span<const Eigen::Vector3f> out, double tolerance) {
  const int n = static_cast<int>(in.size());
  const int k_count = static_cast<int>(out.size());
  if (n == 0 || k_count == 0) return {};
  std::vector<Eigen::Vector3d> prefix(n + 1, Eigen::Vector3d::Zero());
  for (int i = 0; i < n; ++i) prefix[i + 1] = prefix[i] + in[i].cast<double>();
  // from[k][e] = start of the run that ends at e for output k - 1 (-1: not reachable).
  std::vector<std::vector<int>> from(k_count + 1, std::vector<int>(n + 1, -1));
  std::vector<int> frontier = {0};
  from[0][0] = 0;
  for (int k = 0; k < k_count; ++k) {
    std::vector<int> next;
    const Eigen::Vector3d target = out[k].cast<double>();
    const double tol = tolerance * (1.0 + target.cwiseAbs().maxCoeff());
    for (int s : frontier) {
      for (int e = s + 1; e <= n; ++e) {
        const Eigen::Vector3d mean = (prefix[e] - prefix[s]) / double(e - s);
        if ((mean - target).cwiseAbs().maxCoeff() <= tol && from[k + 1][e] < 0) {
          from[k + 1][e] = s;
          next.push_back(e);
        }
      }
    }
    frontier = std::move(next);
  }
  if (from[k_count][n] < 0) return {};
  std::vector<int> lengths(k_count);
  for (int k = k_count, e = n; k > 0; --k) {
    const int s = from[k][e];
    lengths[k - 1] = e - s;
    e = s;
  }
  return lengths;
}

constexpr double kMeanTolerance = 1e-5;  // relative to the coordinate's magnitude: a few float ulps

/// The reduction's contract on one slice: consecutive outputs at least `spacing` apart, and the
/// outputs are the means of a partition of the (median-filtered) input into consecutive runs.
std::vector<int> expect_reduction_contract(const Slice& filtered_input, std::span<const Eigen::Vector3f> out,
                                           double spacing, const std::string& where) {
  for (std::size_t k = 1; k < out.size(); ++k) {
    const double d = (out[k].cast<double>() - out[k - 1].cast<double>()).norm();
    EXPECT_GE(d, spacing * (1.0 - 1e-6)) << where << ": outputs " << k - 1 << " and " << k << " too close";
  }
  if (filtered_input.empty()) {
    EXPECT_TRUE(out.empty()) << where;
    return {};
  }
  const auto runs = partition_into_means(filtered_input, out, kMeanTolerance);
  EXPECT_FALSE(runs.empty()) << where << ": the " << out.size()
                             << " outputs are not the means of consecutive runs of the " << filtered_input.size()
                             << " inputs";
  return runs;
}

std::span<const Eigen::Vector3f> output_slice(const SliceFilterResult& r, std::size_t k) {
  return {r.points_cm.data() + r.slice_offsets[k], r.points_cm.data() + r.slice_offsets[k + 1]};
}

void expect_offsets_consistent(const SliceFilterResult& r, std::size_t expected_slices) {
  ASSERT_EQ(r.slice_offsets.size(), expected_slices + 1);
  EXPECT_EQ(r.slice_offsets.front(), 0u);
  EXPECT_EQ(r.slice_offsets.back(), r.points_out());
  for (std::size_t k = 1; k < r.slice_offsets.size(); ++k) EXPECT_LE(r.slice_offsets[k - 1], r.slice_offsets[k]);
}

/// The median stage alone (reduction off, same stride), through both backends: per kept slice.
std::vector<Slice> median_stage(const Scan& scan, SliceFilterSettings settings) {
  settings.reduction_enabled = false;
  const auto r = filter_both(scan, settings);
  std::vector<Slice> slices;
  for (std::size_t k = 0; k + 1 < r.slice_offsets.size(); ++k) {
    slices.emplace_back(r.points_cm.begin() + r.slice_offsets[k], r.points_cm.begin() + r.slice_offsets[k + 1]);
  }
  return slices;
}

SliceFilterSettings median_only() {
  SliceFilterSettings s;
  s.reduction_enabled = false;
  s.slice_stride = 1;
  return s;
}

SliceFilterSettings reduction_only() {
  SliceFilterSettings s;
  s.median_enabled = false;
  s.slice_stride = 1;
  return s;
}

// ---------------------------------------------------------------------------------------------
// Synthetic slices

/// A smooth wall 300..500 cm away (range 400 + 100 sin 3a), 361 beams over 180 degrees.
Slice smooth_wall_slice(double tilt_rad, double phase) {
  Slice s;
  for (int i = 0; i < 361; ++i) {
    const double a = i * std::numbers::pi / 360.0;
    s.push_back(beam_point(400.0 + 100.0 * std::sin(3.0 * a + phase), a, tilt_rad));
  }
  return s;
}

/// Picks `count` indices of [0, n) pairwise at least `gap` apart (fixed seed), sorted.
std::vector<int> separated_indices(int n, int count, int gap, std::mt19937& rng) {
  std::vector<int> picked;
  std::uniform_int_distribution<int> pick(0, n - 1);
  for (int tries = 0; static_cast<int>(picked.size()) < count && tries < 100000; ++tries) {
    const int c = pick(rng);
    if (std::all_of(picked.begin(), picked.end(), [&](int p) { return std::abs(p - c) >= gap; })) picked.push_back(c);
  }
  std::sort(picked.begin(), picked.end());
  return picked;
}

// =============================================================================================
// Median filter: outlier removal

TEST(SliceFilterMedian, ReplacesExactlyThePlantedOutliersByTheirWindowMedian) {
  std::mt19937 rng(101);
  const auto settings = median_only();
  std::vector<Slice> slices;
  std::vector<std::vector<int>> planted_outliers, planted_moderate;
  std::size_t planted_total = 0;
  for (int s = 0; s < 24; ++s) {
    Slice slice = smooth_wall_slice(0.05 * s - 0.6, 0.3 * s);
    // Planted points are at least a window apart, so no window holds two of them and each
    // window's median is a clean wall point. Indices 0 and 360 (clipped windows) are included.
    auto planted = separated_indices(361, 30, 7, rng);
    if (s == 0) planted = {0, 7, 14, 346, 353, 360};
    std::vector<int> outliers, moderate;
    std::uniform_real_distribution<double> jump(250.0, 1500.0), mild(-170.0, 170.0);
    for (std::size_t k = 0; k < planted.size(); ++k) {
      const int i = planted[k];
      const double r = range_of(slice[i]);
      switch (k % 3) {
        case 0:  // salt: far beyond the wall (reflection)
          slice[i] = at_range(slice[i], r + jump(rng));
          outliers.push_back(i);
          break;
        case 1:  // pepper: much closer (mixed pixel, dust)
          slice[i] = at_range(slice[i], std::uniform_real_distribution<double>(20.0, r - 250.0)(rng));
          outliers.push_back(i);
          break;
        default:  // a real but moderate range jump (< 200 cm from the median): must stay
          slice[i] = at_range(slice[i], r + mild(rng));
          moderate.push_back(i);
          break;
      }
    }
    planted_total += outliers.size();
    planted_outliers.push_back(outliers);
    planted_moderate.push_back(moderate);
    slices.push_back(std::move(slice));
  }
  const Scan scan = make_scan(slices, "planted-outliers");
  const auto result = filter_both(scan, settings);
  expect_offsets_consistent(result, slices.size());
  EXPECT_EQ(result.points_in, scan.size());
  EXPECT_EQ(result.points_in_kept_slices, scan.size());
  EXPECT_EQ(result.points_out(), scan.size());  // median only: one output per input
  EXPECT_EQ(result.outliers_replaced, planted_total);
  for (std::size_t s = 0; s < slices.size(); ++s) {
    const auto out = output_slice(result, s);
    ASSERT_EQ(out.size(), slices[s].size());
    // Every point against the brute-force median; the oracle replaces exactly the planted outliers.
    const auto oracle_replaced = expect_median_filtered(slices[s], out, 7, 200.0, "slice " + std::to_string(s));
    EXPECT_EQ(oracle_replaced, planted_outliers[s]) << "slice " << s;
    for (int i : planted_moderate[s]) EXPECT_EQ(out[i], slices[s][i]) << "moderate jump replaced: slice " << s;
    // Every replacement is a clean neighbour within the window, about 400 +- 100 cm away.
    for (int i : planted_outliers[s]) {
      EXPECT_NEAR(range_of(out[i]), 400.0, 101.0);
      bool from_window = false;
      for (int j = std::max(0, i - 3); j <= std::min(360, i + 3); ++j) from_window |= out[i] == slices[s][j];
      EXPECT_TRUE(from_window) << "slice " << s << " point " << i;
    }
  }
}

TEST(SliceFilterMedian, ThresholdIsStrictAndTiesBreakByIndex) {
  // Axis-aligned points: squared ranges and ranges are exact in float, so the boundary is exact.
  const Slice base = {{100, 0, 0}, {0, 100, 0}, {0, 0, 100}, {0, 300, 0}, {-100, 0, 0}, {0, -100, 0}, {0, 0, -100}};
  auto settings = median_only();
  {
    // |300 - 100| = 200 is not > 200: untouched.
    const auto r = filter_both(make_scan({base}), settings);
    EXPECT_EQ(r.outliers_replaced, 0u);
    EXPECT_EQ(r.points_cm, base);
  }
  {
    Slice s = base;
    s[3] = {0, 300.5f, 0};  // 200.5 > 200: replaced
    const auto r = filter_both(make_scan({s}), settings);
    EXPECT_EQ(r.outliers_replaced, 1u);
    // Window of point 3 sorted by (range, index): 0 1 2 4 5 6 3; the lower median is index 4.
    Slice expected = s;
    expected[3] = s[4];
    EXPECT_EQ(r.points_cm, expected);
  }
  {
    Slice s = base;
    s[3] = {0, 300.5f, 0};
    settings.outlier_threshold_cm = 200.5f;  // equal again: untouched
    const auto r = filter_both(make_scan({s}), settings);
    EXPECT_EQ(r.outliers_replaced, 0u);
    EXPECT_EQ(r.points_cm, s);
  }
  {
    // Threshold 0: every point whose range differs at all from its window median is replaced.
    Slice s = {{100, 0, 0}, {0, 101, 0}, {0, 0, 102}, {103, 0, 0}, {0, 104, 0}};
    settings.outlier_threshold_cm = 0.0f;
    settings.median_window = 3;
    const auto r = filter_both(make_scan({s}), settings);
    // Windows (lower median): {0,1}->0, {0,1,2}->1, {1,2,3}->2, {2,3,4}->3, {3,4}->3.
    EXPECT_EQ(r.points_cm, (Slice{s[0], s[1], s[2], s[3], s[3]}));
    EXPECT_EQ(r.outliers_replaced, 1u);
  }
}

TEST(SliceFilterMedian, ShortSlicesUseTheClippedWindow) {
  // Slices shorter than the window (1, 2, 3, 6 points) and windows of other sizes, each against
  // the brute-force oracle; ranges drawn so that some points are outliers of their window.
  std::mt19937 rng(202);
  std::uniform_real_distribution<double> range(50.0, 900.0), angle(0.0, std::numbers::pi);
  for (int window : {1, 3, 5, 7, 9, 31}) {
    std::vector<Slice> slices;
    for (int length : {1, 2, 3, 4, 5, 6, 7, 8, 13, 40}) {
      for (int rep = 0; rep < 3; ++rep) {
        Slice s;
        for (int i = 0; i < length; ++i) s.push_back(beam_point(range(rng), angle(rng), 0.3 * rep));
        slices.push_back(s);
      }
    }
    slices.push_back({});           // an empty slice in the middle of others
    slices.push_back({{0, 0, 0}});  // a point at the scanner origin (range 0)
    auto settings = median_only();
    settings.median_window = window;
    const Scan scan = make_scan(slices, "short-w" + std::to_string(window));
    const auto r = filter_both(scan, settings);
    expect_offsets_consistent(r, slices.size());
    std::size_t replaced = 0;
    for (std::size_t s = 0; s < slices.size(); ++s) {
      const auto rep = expect_median_filtered(slices[s], output_slice(r, s), window, 200.0,
                                              "window " + std::to_string(window) + " slice " + std::to_string(s));
      replaced += rep.size();
      if (window == 1) {
        EXPECT_TRUE(rep.empty());  // a window of one is the point itself
      }
    }
    EXPECT_EQ(r.outliers_replaced, replaced) << "window " << window;
    if (window == 7) {
      EXPECT_GT(replaced, 10u);  // the data did exercise replacement
    }
  }
}

TEST(SliceFilterMedian, TwoPointSliceKeepsTheNearerPoint) {
  // With an even clipped window the LOWER median is used, so of two points more than 200 cm apart
  // in range the nearer one wins (documented behaviour, pinned here).
  const Slice s = {{100, 0, 0}, {0, 400, 0}};
  const auto r = filter_both(make_scan({s}), median_only());
  EXPECT_EQ(r.points_cm, (Slice{s[0], s[0]}));
  EXPECT_EQ(r.outliers_replaced, 1u);
}

// =============================================================================================
// Reduction

TEST(SliceFilterReduction, UniformChainGivesMeansExactlyTenCentimetresApart) {
  // 100 points 1 cm apart on a line: runs of 10 (anchor + 9 closer than 10 cm), means exact.
  Slice s;
  for (int i = 0; i < 100; ++i) s.emplace_back(300.0f + static_cast<float>(i), 20.0f, -5.0f);
  const auto r = filter_both(make_scan({s}), reduction_only());
  ASSERT_EQ(r.points_out(), 10u);
  for (int k = 0; k < 10; ++k) EXPECT_EQ(r.points_cm[k], Eigen::Vector3f(304.5f + 10.0f * k, 20.0f, -5.0f));
  expect_reduction_contract(s, r.points_cm, 10.0, "chain");
}

TEST(SliceFilterReduction, CloseClusterMeansAreMergedWithWeights) {
  // 0, 6, 12: run {0, 6} -> 3 (weight 2); run {12} is 9 cm from it -> merged: (2*3 + 12) / 3 = 6.
  const Slice s = {{0, 0, 200}, {6, 0, 200}, {12, 0, 200}};
  const auto r = filter_both(make_scan({s}), reduction_only());
  EXPECT_EQ(r.points_cm, (Slice{{6, 0, 200}}));
  // 0, 6, 12, 30, 36: {0,6}->3, {12}->merge->6 (w3), {30,36}->33: 27 cm from 6, kept.
  const Slice t = {{0, 0, 200}, {6, 0, 200}, {12, 0, 200}, {30, 0, 200}, {36, 0, 200}};
  const auto r2 = filter_both(make_scan({t}), reduction_only());
  EXPECT_EQ(r2.points_cm, (Slice{{6, 0, 200}, {33, 0, 200}}));
  // A cascade: runs whose means creep back toward the previous output are folded in repeatedly.
  Slice u;
  for (float x : {0.f, 9.f, 9.5f, 18.f, 18.5f, 19.f, 27.f}) u.emplace_back(x, 100.f, 0.f);
  const auto r3 = filter_both(make_scan({u}), reduction_only());
  expect_reduction_contract(u, r3.points_cm, 10.0, "cascade");
}

TEST(SliceFilterReduction, GaussianNoiseOnAPlaneIsReduced) {
  // Planes (walls y = D in the slice plane, 250..400 cm away, various tilts) seen by 361-beam
  // slices, with isotropic Gaussian noise sigma = 1 cm. A mean of L points has sigma / sqrt(L).
  std::mt19937 rng(303);
  std::normal_distribution<double> noise(0.0, 1.0);
  const int slices_count = 40;
  std::vector<Slice> slices;
  std::vector<Eigen::Vector3d> normals;
  std::vector<double> distances;
  for (int s = 0; s < slices_count; ++s) {
    const double tilt = -0.7 + 1.4 * s / (slices_count - 1);
    const double wall = 250.0 + 150.0 * (s % 5) / 4.0;
    const Eigen::Vector3d normal(0.0, std::cos(tilt), std::sin(tilt));  // the wall plane: n.x = wall
    Slice slice;
    for (int i = 0; i < 361; ++i) {
      const double a = i * std::numbers::pi / 360.0;
      if (std::sin(a) < 0.55) continue;  // beams that hit the wall within ~730 cm
      const Eigen::Vector3d d = beam_point(1.0, a, tilt).cast<double>().normalized();
      const Eigen::Vector3d hit = d * (wall / d.dot(normal)) + Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
      slice.push_back(hit.cast<float>());
    }
    slices.push_back(std::move(slice));
    normals.push_back(normal);
    distances.push_back(wall);
  }
  SliceFilterSettings settings;  // the paper's full filter: median (no outliers here) + reduction
  settings.slice_stride = 1;
  const Scan scan = make_scan(slices, "noisy-planes");
  const auto r = filter_both(scan, settings);
  expect_offsets_consistent(r, slices.size());
  EXPECT_EQ(r.outliers_replaced, 0u);
  double in_sq = 0.0, out_sq = 0.0, predicted_sq = 0.0;
  std::size_t in_n = 0, out_n = 0;
  for (int s = 0; s < slices_count; ++s) {
    const auto out = output_slice(r, s);
    const auto runs = expect_reduction_contract(slices[s], out, 10.0, "plane slice " + std::to_string(s));
    ASSERT_EQ(runs.size(), out.size());
    for (const auto& p : slices[s]) {
      in_sq += std::pow(normals[s].dot(p.cast<double>()) - distances[s], 2);
      ++in_n;
    }
    for (std::size_t k = 0; k < out.size(); ++k) {
      out_sq += std::pow(normals[s].dot(out[k].cast<double>()) - distances[s], 2);
      predicted_sq += 1.0 / runs[k];  // sigma^2 / L
      ++out_n;
    }
  }
  const double rms_in = std::sqrt(in_sq / in_n), rms_out = std::sqrt(out_sq / out_n);
  const double rms_predicted = std::sqrt(predicted_sq / out_n);  // sigma = 1
  const double ratio = double(in_n) / double(out_n);
  RecordProperty("rms_in_cm", std::to_string(rms_in));
  RecordProperty("rms_out_cm", std::to_string(rms_out));
  std::printf("[ noise    ] %zu -> %zu points (x%.2f); plane RMS %.3f -> %.3f cm (predicted %.3f)\n", in_n, out_n,
              ratio, rms_in, rms_out, rms_predicted);
  EXPECT_NEAR(rms_in, 1.0, 0.05);
  EXPECT_GT(ratio, 2.5);
  EXPECT_LT(rms_out, 0.75 * rms_in);
  EXPECT_LT(rms_out, rms_in / std::sqrt(ratio) * 1.6);  // roughly sigma / sqrt(points joined)
  EXPECT_NEAR(rms_out / rms_predicted, 1.0, 0.25);
}

TEST(SliceFilterReduction, PointsWithinTenCentimetresCollapseToTheirMean) {
  std::mt19937 rng(404);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  Slice s;
  const Eigen::Vector3f centre(300.f, 50.f, 20.f);
  while (s.size() < 100) {
    const Eigen::Vector3f d(u(rng), u(rng), u(rng));
    if (d.norm() <= 1.f) s.push_back(centre + 4.9f * d);  // pairwise closer than 9.8 cm
  }
  const auto r = filter_both(make_scan({s}), reduction_only());
  ASSERT_EQ(r.points_out(), 1u);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : s) mean += p.cast<double>();
  mean /= double(s.size());
  EXPECT_LT((r.points_cm[0].cast<double>() - mean).norm(), 1e-3);
}

TEST(SliceFilterReduction, DuplicatePoints) {
  // Pairs of duplicates 20 cm apart: each pair becomes exactly its point ((p + p) / 2 == p).
  Slice pairs;
  for (int i = 0; i < 30; ++i) {
    const Eigen::Vector3f p(250.f, -100.f + 20.f * i + 0.37f, 33.3f);
    pairs.push_back(p);
    pairs.push_back(p);
  }
  Slice expected;
  for (std::size_t i = 0; i < pairs.size(); i += 2) expected.push_back(pairs[i]);
  EXPECT_EQ(filter_both(make_scan({pairs}), reduction_only()).points_cm, expected);
  // 361 copies of one point: one output, the float mean of the copies. The running float sum
  // (up to 361 * 401.25 = 144,851, ulp 0.0156) rounds, so the mean is off by a few micrometres
  // (measured 2.5e-4 cm on z): a legitimate float difference, bounded here by 1e-3 cm.
  const Eigen::Vector3f p(123.456f, -78.9f, 401.25f);
  const Slice copies(361, p);
  const auto r = filter_both(make_scan({copies}), reduction_only());
  ASSERT_EQ(r.points_out(), 1u);
  EXPECT_LT((r.points_cm[0] - p).cwiseAbs().maxCoeff(), 1e-3f);
  // Spacing 0: nothing joins, duplicates included; the output is the input, bit for bit.
  auto zero = reduction_only();
  zero.min_point_spacing_cm = 0.0f;
  EXPECT_EQ(filter_both(make_scan({pairs, copies}), zero).points_cm, [&] {
    Slice all = pairs;
    all.insert(all.end(), copies.begin(), copies.end());
    return all;
  }());
}

TEST(SliceFilterReduction, RandomSlicesSatisfyTheContractForAnySpacing) {
  // Random walks (small and large steps, so both joins and gaps occur) against the partition
  // oracle, for several spacings; median and reduction together.
  std::mt19937 rng(505);
  std::normal_distribution<float> step(0.f, 4.f);
  for (float spacing : {1.0f, 5.0f, 10.0f, 25.0f}) {
    std::vector<Slice> slices;
    for (int s = 0; s < 20; ++s) {
      Slice slice;
      Eigen::Vector3f p(300.f, 0.f, 100.f);
      const int n = 1 + static_cast<int>(rng() % 361);
      for (int i = 0; i < n; ++i) {
        p += Eigen::Vector3f(step(rng), step(rng), step(rng)) * ((i % 37 == 0) ? 8.f : 1.f);
        slice.push_back(p);
      }
      slices.push_back(slice);
    }
    SliceFilterSettings settings;
    settings.slice_stride = 1;
    settings.min_point_spacing_cm = spacing;
    const Scan scan = make_scan(slices, "walks");
    const auto r = filter_both(scan, settings);
    const auto medians = median_stage(scan, settings);
    expect_offsets_consistent(r, slices.size());
    std::size_t replaced = 0;
    for (std::size_t s = 0; s < slices.size(); ++s) {
      const std::string where = "spacing " + std::to_string(spacing) + " slice " + std::to_string(s);
      replaced +=
          expect_median_filtered(slices[s], medians[s], settings.median_window, settings.outlier_threshold_cm, where)
              .size();
      expect_reduction_contract(medians[s], output_slice(r, s), spacing, where);
    }
    EXPECT_EQ(r.outliers_replaced, replaced);
  }
}

// =============================================================================================
// Vertical reduction, counts, edge cases

TEST(SliceFilterSlices, KeepsEveryStrideThSliceAndFiltersEachAlone) {
  std::mt19937 rng(606);
  std::vector<Slice> slices;
  for (int s = 0; s < 20; ++s) {
    Slice slice = smooth_wall_slice(0.04 * s, 0.1 * s);
    slice.resize(100 + 13 * s);
    if (s % 4 == 1) slice[rng() % slice.size()] *= 3.0f;  // an outlier now and then
    if (s == 9) slice.clear();                            // an empty kept slice
    slices.push_back(slice);
  }
  const Scan scan = make_scan(slices, "stride");
  for (int stride : {1, 2, 3, 7, 19, 20, 1000}) {
    SliceFilterSettings settings;
    settings.slice_stride = stride;
    const auto r = filter_both(scan, settings);
    std::vector<std::size_t> kept;
    for (std::size_t s = 0; s < slices.size(); s += stride) kept.push_back(s);
    expect_offsets_consistent(r, kept.size());
    std::size_t kept_points = 0, replaced = 0;
    for (std::size_t k = 0; k < kept.size(); ++k) {
      kept_points += slices[kept[k]].size();
      // The kept slice filtered on its own gives the same bits.
      auto alone_settings = settings;
      alone_settings.slice_stride = 1;
      const auto alone = filter_scan_cpu(make_scan({slices[kept[k]]}), alone_settings);
      replaced += alone.outliers_replaced;
      const auto out = output_slice(r, k);
      ASSERT_EQ(out.size(), alone.points_out()) << "stride " << stride << " slice " << kept[k];
      for (std::size_t i = 0; i < out.size(); ++i) EXPECT_EQ(out[i], alone.points_cm[i]);
    }
    EXPECT_EQ(r.points_in, scan.size());
    EXPECT_EQ(r.points_in_kept_slices, kept_points) << "stride " << stride;
    EXPECT_EQ(r.outliers_replaced, replaced);
    if (stride == 3) {
      EXPECT_EQ(kept, (std::vector<std::size_t>{0, 3, 6, 9, 12, 15, 18}));
    }
  }
}

TEST(SliceFilterSlices, EmptyAndOnePointSlices) {
  const Slice one = {{10.f, 200.f, -3.f}};
  std::vector<Slice> slices = {{}, one, {}, {}, one, {{1.f, 2.f, 3.f}}, {}};
  const Scan scan = make_scan(slices, "sparse");
  for (bool median : {false, true}) {
    SliceFilterSettings settings;
    settings.slice_stride = 1;
    settings.median_enabled = median;
    const auto r = filter_both(scan, settings);
    expect_offsets_consistent(r, slices.size());
    EXPECT_EQ(r.slice_offsets, (std::vector<std::uint32_t>{0, 0, 1, 1, 1, 2, 3, 3}));
    EXPECT_EQ(r.points_cm, (Slice{one[0], one[0], {1.f, 2.f, 3.f}}));
    EXPECT_EQ(r.outliers_replaced, 0u);
  }
}

TEST(SliceFilterSlices, ScanWhoseSlicesAreAllEmpty) {
  // Slice structure but no points (every beam without return): the kept slices are all empty.
  Scan scan;
  scan.name = "no-returns";
  scan.slice_offsets = {0, 0, 0, 0, 0, 0};  // 5 slices
  SliceFilterSettings settings;             // stride 3: slices 0 and 3
  const auto r = filter_both(scan, settings);
  EXPECT_EQ(r.points_out(), 0u);
  EXPECT_EQ(r.slice_offsets, (std::vector<std::uint32_t>{0, 0, 0}));
}

TEST(SliceFilterSlices, ScanWithoutSlicesIsReturnedUnchangedWithANote) {
  Scan scan;
  scan.name = "unstructured";
  scan.points_cm = test::random_cloud(500, -300.f, 300.f, 7);
  CpuBackend cpu_backend;
  for (ComputeBackend* backend : {static_cast<ComputeBackend*>(&cpu_backend), &opencl()}) {
    const auto r = backend->filter_slices(scan, SliceFilterSettings{});
    EXPECT_EQ(r.backend, backend->name());
    EXPECT_EQ(r.points_cm, scan.points_cm);
    EXPECT_EQ(r.slice_offsets, (std::vector<std::uint32_t>{0, 500}));
    EXPECT_EQ(r.points_in, 500u);
    EXPECT_EQ(r.points_in_kept_slices, 500u);
    EXPECT_EQ(r.outliers_replaced, 0u);
  }
  // The backends called directly behave the same.
  const auto cpu = filter_scan_cpu(scan, SliceFilterSettings{});
  const auto gpu = run_opencl(scan, SliceFilterSettings{});
  EXPECT_EQ(cpu.points_cm, scan.points_cm);
  EXPECT_EQ(gpu.points_cm, scan.points_cm);
  EXPECT_EQ(gpu.slice_offsets, cpu.slice_offsets);
  EXPECT_EQ(thin_unstructured(scan, 1), scan.points_cm);
  const auto thinned = thin_unstructured(scan, 3);
  ASSERT_EQ(thinned.size(), 167u);
  for (std::size_t i = 0; i < thinned.size(); ++i) EXPECT_EQ(thinned[i], scan.points_cm[3 * i]);
  // Mapping says so, once: the note names what was skipped.
  Scan second = scan;
  second.name = "unstructured2";
  const auto mapped = map_survey({scan, second}, MappingSettings::simultaneous(), cpu_backend);
  std::string notes;
  for (const auto& note : mapped.notes) notes += note + "\n";
  EXPECT_NE(notes.find("without slice structure: slice filter skipped"), std::string::npos) << notes;
  EXPECT_EQ(mapped.notes.size(), 1u) << notes;
}

TEST(SliceFilterDispatch, UsesTheRequestedBackend) {
  const Scan scan = make_scan({smooth_wall_slice(0.1, 0.0), smooth_wall_slice(0.2, 0.5)}, "dispatch");
  const auto gpu = opencl().filter_slices(scan, SliceFilterSettings{});
  EXPECT_EQ(gpu.backend, "opencl");
  const auto cpu = make_cpu_backend()->filter_slices(scan, SliceFilterSettings{});
  EXPECT_EQ(cpu.backend, "cpu");
  EXPECT_EQ(cpu.points_cm, gpu.points_cm);
  EXPECT_EQ(cpu.slice_offsets, gpu.slice_offsets);
  // Auto: OpenCL only on a GPU; on a machine with PoCL alone the CPU backend, saying why.
  const BackendChoice choice = make_backend(backend_options_from_environment(Backend::kAuto));
  const std::string& note = choice.message;
  const auto automatic = choice.backend->filter_slices(scan, SliceFilterSettings{});
  if (automatic.backend == "cpu") {
    EXPECT_NE(note.find("CPU backend (TBB): "), std::string::npos) << note;
  } else {
    EXPECT_EQ(automatic.backend, "opencl");
    EXPECT_EQ(note.rfind("OpenCL backend: ", 0), 0u) << note;
  }
  EXPECT_EQ(automatic.points_cm, cpu.points_cm);
}

TEST(SliceFilterSettingsTest, InvalidSettingsThrow) {
  const Scan scan = make_scan({smooth_wall_slice(0.0, 0.0)});
  Scan unstructured;
  unstructured.points_cm = {{1, 2, 3}};
  auto bad = [](auto mutate) {
    SliceFilterSettings s;
    mutate(s);
    return s;
  };
  const std::vector<std::pair<std::string, SliceFilterSettings>> cases = {
      {"even window", bad([](auto& s) { s.median_window = 6; })},
      {"window 0", bad([](auto& s) { s.median_window = 0; })},
      {"negative window", bad([](auto& s) { s.median_window = -7; })},
      {"window 33", bad([](auto& s) { s.median_window = 33; })},
      {"window 32", bad([](auto& s) { s.median_window = 32; })},
      {"negative spacing", bad([](auto& s) { s.min_point_spacing_cm = -1.0f; })},
      {"NaN spacing", bad([](auto& s) { s.min_point_spacing_cm = std::nanf(""); })},
      {"infinite spacing", bad([](auto& s) { s.min_point_spacing_cm = INFINITY; })},
      {"negative threshold", bad([](auto& s) { s.outlier_threshold_cm = -0.5f; })},
      {"NaN threshold", bad([](auto& s) { s.outlier_threshold_cm = std::nanf(""); })},
      {"stride 0", bad([](auto& s) { s.slice_stride = 0; })},
      {"negative stride", bad([](auto& s) { s.slice_stride = -3; })},
  };
  for (const auto& [what, s] : cases) {
    EXPECT_THROW(s.validate(), std::invalid_argument) << what;
    EXPECT_THROW(filter_scan_cpu(scan, s), std::invalid_argument) << what;
    EXPECT_THROW(make_cpu_backend()->filter_slices(scan, s), std::invalid_argument) << what;
    EXPECT_THROW(opencl().filter_slices(scan, s), std::invalid_argument) << what;
    EXPECT_THROW(make_cpu_backend()->filter_slices(unstructured, s), std::invalid_argument) << what;
    EXPECT_THROW(opencl().filter_slices(unstructured, s), std::invalid_argument) << what;
  }
  // The limits themselves are valid.
  for (int w : {1, 3, 31}) {
    SliceFilterSettings s;
    s.median_window = w;
    EXPECT_NO_THROW(s.validate()) << w;
    EXPECT_NO_THROW(filter_both(scan, s)) << w;
  }
  SliceFilterSettings zero;
  zero.min_point_spacing_cm = 0.0f;
  zero.outlier_threshold_cm = 0.0f;
  zero.slice_stride = 1;
  EXPECT_NO_THROW(zero.validate());
}

TEST(SliceFilterBackends, RandomSettingsAndAdversarialInputsAgreeBitForBit) {
  // Random settings on random inputs, including clouds 1 km from the origin, sub-millimetre
  // coordinates, exact ties in range, and slices of every small length.
  std::mt19937 rng(707);
  std::uniform_real_distribution<float> unit(-1.f, 1.f);
  for (int trial = 0; trial < 24; ++trial) {
    std::vector<Slice> slices;
    const int slice_count = 1 + static_cast<int>(rng() % 40);
    const float scale = std::array<float, 4>{1e-3f, 1.f, 300.f, 5000.f}[trial % 4];
    const Eigen::Vector3f offset = (trial % 3 == 0) ? Eigen::Vector3f(1e5f, -2e4f, 5e4f) : Eigen::Vector3f::Zero();
    for (int s = 0; s < slice_count; ++s) {
      Slice slice;
      const int n = static_cast<int>(rng() % 120);
      for (int i = 0; i < n; ++i) {
        if (i > 0 && rng() % 5 == 0) {
          slice.push_back(slice.back());  // exact duplicate (tie)
        } else if (i > 0 && rng() % 7 == 0) {
          slice.push_back(-slice.back() + 2.0f * offset);  // same range, mirrored (tie) near origin
        } else {
          slice.push_back(offset + scale * Eigen::Vector3f(unit(rng), unit(rng), unit(rng)));
        }
      }
      slices.push_back(slice);
    }
    SliceFilterSettings settings;
    settings.median_enabled = rng() % 4 != 0;
    settings.reduction_enabled = rng() % 4 != 0;
    settings.median_window = 1 + 2 * static_cast<int>(rng() % 16);
    settings.outlier_threshold_cm = scale * std::uniform_real_distribution<float>(0.f, 1.5f)(rng);
    settings.min_point_spacing_cm = scale * std::uniform_real_distribution<float>(0.f, 0.8f)(rng);
    settings.slice_stride = 1 + static_cast<int>(rng() % 4);
    filter_both(make_scan(slices, "random-" + std::to_string(trial)), settings);
  }
}

// =============================================================================================
// A paper-size scan: 341 slices x 361 beams of a tunnel

/// A tilting 2D scanner in a mine tunnel: walls at x = -220 / +260, floor y = -110, roof
/// y = +190, face 2500 cm ahead (z), optional pillar; beam angle a in [0, 180] degrees in the
/// slice plane, slice tilt t in [5, 175] degrees about the x axis (341 slices of 0.5 degrees).
Scan paper_size_tunnel_scan(std::uint32_t seed, std::size_t* planted_outliers) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.8);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Slice> slices;
  *planted_outliers = 0;
  int since_outlier = 100;
  for (int s = 0; s < 341; ++s) {
    const double tilt = (5.0 + 0.5 * s) * std::numbers::pi / 180.0;
    Slice slice;
    for (int i = 0; i < 361; ++i) {
      const double a = i * std::numbers::pi / 360.0;
      const Eigen::Vector3d d = beam_point(1.0, a, tilt).cast<double>();
      double t = std::numeric_limits<double>::infinity();
      auto hit = [&](double coordinate, double limit) {
        if (coordinate != 0.0 && limit / coordinate > 0.0) t = std::min(t, limit / coordinate);
      };
      hit(d.x(), -220.0);
      hit(d.x(), 260.0);
      hit(d.y(), -110.0);
      hit(d.y(), 190.0);
      hit(d.z(), 2500.0);
      // A pillar (vertical cylinder of radius 60 at x = 120, z = 700).
      const double px = d.x(), pz = d.z();
      const double b = px * 120.0 + pz * 700.0, c = 120.0 * 120.0 + 700.0 * 700.0 - 60.0 * 60.0;
      const double aa = px * px + pz * pz;
      const double disc = b * b - aa * c;
      if (aa > 0 && disc >= 0) {
        const double tc = (b - std::sqrt(disc)) / aa;
        if (tc > 0) t = std::min(t, tc);
      }
      double range = t + noise(rng);
      ++since_outlier;
      if (since_outlier > 8 && u01(rng) < 0.01) {  // salt and pepper, about 1 %
        range = u01(rng) < 0.5 ? range + 300.0 + 2000.0 * u01(rng) : 10.0 + (range - 260.0) * u01(rng);
        if (range > 0) {
          since_outlier = 0;
          ++*planted_outliers;
        } else {
          range = t;
        }
      }
      slice.push_back((d * range).cast<float>());
    }
    slices.push_back(std::move(slice));
  }
  return make_scan(slices, "paper-size-tunnel");
}

TEST(SliceFilterPaperSize, TunnelScanReducesByAboutAnOrderOfMagnitude) {
  std::size_t planted = 0;
  const Scan scan = paper_size_tunnel_scan(808, &planted);
  ASSERT_EQ(scan.size(), 123101u);     // the paper's scan: 341 x 361 = 123,101 points
  const SliceFilterSettings settings;  // paper defaults: n = 7, 200 cm, 10 cm, every third slice
  const auto r = filter_both(scan, settings);
  expect_offsets_consistent(r, 114);  // slices 0, 3, ..., 339
  EXPECT_EQ(r.points_in, 123101u);
  EXPECT_EQ(r.points_in_kept_slices, 114u * 361u);
  const double ratio = double(r.points_in) / double(r.points_out());
  std::printf(
      "[ paper    ] %zu points -> %zu (x%.1f; paper: 123101 -> 10535, x11.7); %zu outliers replaced "
      "in kept slices (%zu planted in all slices)\n",
      r.points_in, r.points_out(), ratio, r.outliers_replaced, planted);
  EXPECT_GT(ratio, 6.0);
  EXPECT_LT(ratio, 25.0);
  // Planted outliers are a few hundred per scan; a third of the slices are kept.
  EXPECT_GT(r.outliers_replaced, planted / 3 / 2);
  EXPECT_LT(r.outliers_replaced, planted / 3 * 2);
  // The contract on every kept slice, against the brute-force median and the partition oracle.
  const auto medians = median_stage(scan, settings);
  std::size_t replaced = 0;
  for (std::size_t k = 0; k < 114; ++k) {
    const std::string where = "tunnel slice " + std::to_string(3 * k);
    const Slice in(scan.slice(3 * k).begin(), scan.slice(3 * k).end());
    replaced += expect_median_filtered(in, medians[k], 7, 200.0, where).size();
    expect_reduction_contract(medians[k], output_slice(r, k), 10.0, where);
  }
  EXPECT_EQ(r.outliers_replaced, replaced);
}

// Reports the CPU-vs-OpenCL agreement over every input this process filtered (each mismatch has
// already failed its own test through filter_both; this line only summarises).
class AgreementReport : public ::testing::Environment {
 public:
  void TearDown() override {
    const auto& log = agreement();
    std::printf(
        "[ agree    ] %zu inputs through both backends, %zu output points compared, %zu bitwise "
        "differences, max |cpu - opencl| = %g cm\n",
        log.inputs, log.points_compared, log.bitwise_differences, log.max_abs_difference_cm);
  }
};
[[maybe_unused]] const auto* const kAgreementReport = ::testing::AddGlobalTestEnvironment(new AgreementReport);

}  // namespace
}  // namespace minemap

namespace minemap {
namespace {

TEST(SliceFilterSimulatedMine, ReducesAPaperSizeMineScanByAboutAnOrderOfMagnitude) {
  // The paper: 123,101 points -> 10,535 reduced points (x11.7) inside the Mathies mine. The
  // simulated mine gives x9.3 and x6.6 for its first two scans: it has longer sight lines (down the
  // drive and into cross-cuts), where points are already more than 10 cm apart.
  sim::SimulationSettings settings;
  settings.mine.scans = 2;
  const auto survey = sim::simulate_mine_survey(settings);
  for (const Scan& scan : survey.scans) {
    const SliceFilterResult result = filter_both(scan, SliceFilterSettings{});
    const double ratio = static_cast<double>(result.points_in) / static_cast<double>(result.points_out());
    std::printf("%s: %zu -> %zu points (x%.1f), %zu outliers replaced\n", scan.name.c_str(), result.points_in,
                result.points_out(), ratio, result.outliers_replaced);
    EXPECT_GT(result.points_in, 120000u);
    EXPECT_GT(ratio, 5.0);
    EXPECT_LT(ratio, 16.0);
    EXPECT_GT(result.outliers_replaced, 0u);  // the simulated mixed pixels and reflections
  }
}

}  // namespace
}  // namespace minemap
