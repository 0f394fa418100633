#include "minemap/sim/gradient_noise.hpp"

#include <cmath>
#include <numbers>

#include "minemap/sim/sim_random.hpp"

namespace minemap::sim {
namespace {

/// Gradient directions on the lattice: 16 evenly spaced unit vectors.
constexpr int kGradientCount = 16;

/// 2D Perlin noise with unit gradients peaks near sqrt(2)/2; this scales it to about [-1, 1].
constexpr double kPerlinScale = std::numbers::sqrt2;
static_assert(kGradientCount == 16, "lattice_gradient picks a gradient with 4 hash bits");

struct Gradient {
  double x;
  double y;
};

const std::array<Gradient, kGradientCount>& gradient_table() {
  // Function-local static: initialised once, thread-safe (C++11 magic statics).
  static const std::array<Gradient, kGradientCount> table = [] {
    std::array<Gradient, kGradientCount> t{};
    for (int i = 0; i < kGradientCount; ++i) {
      const double a = 2.0 * std::numbers::pi * (i + 0.5) / kGradientCount;
      t[i] = {std::cos(a), std::sin(a)};
    }
    return t;
  }();
  return table;
}

/// Odd multipliers that spread lattice coordinates before the mix (a Weyl-style 2D hash).
constexpr std::uint64_t kLatticeMulI = 0x9e3779b97f4a7c15ULL;
constexpr std::uint64_t kLatticeMulJ = 0xc2b2ae3d27d4eb4fULL;

inline const Gradient& lattice_gradient(const std::array<Gradient, kGradientCount>& table, std::int64_t i,
                                        std::int64_t j, std::uint64_t seed) {
  const std::uint64_t h = mix64(seed + static_cast<std::uint64_t>(i) * kLatticeMulI +
                                static_cast<std::uint64_t>(j) * kLatticeMulJ);
  return table[h >> 60];  // top 4 bits: one of 16 gradients
}

/// Quintic fade 6t^5 - 15t^4 + 10t^3 (C2 continuous, so the surfaces have continuous normals).
inline double fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }
inline double fade_derivative(double t) { return 30.0 * t * t * (t * (t - 2.0) + 1.0); }

}  // namespace

FieldSample gradient_noise_2d(double u, double v, std::uint64_t seed) {
  const double fu = std::floor(u);
  const double fv = std::floor(v);
  const auto i = static_cast<std::int64_t>(fu);
  const auto j = static_cast<std::int64_t>(fv);
  const double x = u - fu;
  const double y = v - fv;

  const auto& table = gradient_table();
  const Gradient& g00 = lattice_gradient(table, i, j, seed);
  const Gradient& g10 = lattice_gradient(table, i + 1, j, seed);
  const Gradient& g01 = lattice_gradient(table, i, j + 1, seed);
  const Gradient& g11 = lattice_gradient(table, i + 1, j + 1, seed);

  const double a = g00.x * x + g00.y * y;
  const double b = g10.x * (x - 1.0) + g10.y * y;
  const double c = g01.x * x + g01.y * (y - 1.0);
  const double d = g11.x * (x - 1.0) + g11.y * (y - 1.0);

  const double fx = fade(x);
  const double fy = fade(y);
  const double dfx = fade_derivative(x);
  const double dfy = fade_derivative(y);
  const double k1 = b - a;
  const double k2 = c - a;
  const double k3 = a - b - c + d;

  FieldSample s;
  s.value = a + fx * k1 + fy * k2 + fx * fy * k3;
  s.d_du = g00.x + fx * (g10.x - g00.x) + fy * (g01.x - g00.x) + fx * fy * (g00.x - g10.x - g01.x + g11.x) +
           dfx * (k1 + fy * k3);
  s.d_dv = g00.y + fx * (g10.y - g00.y) + fy * (g01.y - g00.y) + fx * fy * (g00.y - g10.y - g01.y + g11.y) +
           dfy * (k2 + fx * k3);
  s.value *= kPerlinScale;
  s.d_du *= kPerlinScale;
  s.d_dv *= kPerlinScale;
  return s;
}

RoughnessField::RoughnessField(std::uint64_t seed, std::span<const NoiseOctave> octaves) {
  CounterRng rng(seed);
  for (const NoiseOctave& octave : octaves) {
    if (count_ == kMaxOctaves) break;
    if (!(octave.amplitude_cm > 0.0) || !(octave.wavelength_cm > 0.0)) continue;
    Layer& layer = layers_[count_++];
    layer.inv_wavelength = 1.0 / octave.wavelength_cm;
    layer.amplitude = octave.amplitude_cm;
    const double angle = rng.uniform(0.0, 2.0 * std::numbers::pi);
    layer.cos_a = std::cos(angle);
    layer.sin_a = std::sin(angle);
    layer.offset_u = rng.uniform(0.0, 1.0);
    layer.offset_v = rng.uniform(0.0, 1.0);
    layer.seed = rng.next_bits();
    bound_cm_ += octave.amplitude_cm;
    slope_bound_ += octave.amplitude_cm * kGradientNoiseSlopeBound / octave.wavelength_cm;
  }
}

FieldSample RoughnessField::sample(double u_cm, double v_cm) const {
  FieldSample total;
  for (int k = 0; k < count_; ++k) {
    const Layer& l = layers_[k];
    const double uu = (l.cos_a * u_cm - l.sin_a * v_cm) * l.inv_wavelength + l.offset_u;
    const double vv = (l.sin_a * u_cm + l.cos_a * v_cm) * l.inv_wavelength + l.offset_v;
    const FieldSample n = gradient_noise_2d(uu, vv, l.seed);
    const double scale = l.amplitude * l.inv_wavelength;
    total.value += l.amplitude * n.value;
    total.d_du += scale * (n.d_du * l.cos_a + n.d_dv * l.sin_a);
    total.d_dv += scale * (-n.d_du * l.sin_a + n.d_dv * l.cos_a);
  }
  return total;
}

}  // namespace minemap::sim
