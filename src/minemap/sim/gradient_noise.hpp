#pragma once
// Smooth random fields for rough rock: 2D gradient (Perlin) noise with analytic derivatives, summed
// over a few octaves. The simulator displaces ribs, floor and roof by such fields evaluated at WORLD
// coordinates, so a bump looks the same from every scan pose; the derivatives let ray casting solve
// ray-versus-rough-surface intersections with Newton steps.
//
// Thread-safety: immutable after construction; sample() is const and safe from any thread.
#include <array>
#include <cstdint>
#include <span>

namespace minemap::sim {

/// A value and its gradient with respect to the two field coordinates (cm).
struct FieldSample {
  double value = 0.0;
  double d_du = 0.0;
  double d_dv = 0.0;
};

/// One octave: features about `wavelength_cm` across, values within +-`amplitude_cm`.
struct NoiseOctave {
  double wavelength_cm = 100.0;
  double amplitude_cm = 1.0;
};

/// 2D gradient noise on the unit lattice, scaled to about [-1, 1]; value and derivatives.
FieldSample gradient_noise_2d(double u, double v, std::uint64_t seed);

/// Bound of |gradient| of gradient_noise_2d per lattice unit. Sampled maximum over 8 million
/// points: 2.89; the bound keeps a margin. Ray casting uses it to skip surfaces a ray cannot reach.
inline constexpr double kGradientNoiseSlopeBound = 4.0;

/// A sum of gradient-noise octaves, each on its own randomly rotated and shifted lattice (no
/// axis-aligned artefacts, no shared zero crossings at the origin).
class RoughnessField {
 public:
  static constexpr int kMaxOctaves = 4;

  RoughnessField() = default;
  RoughnessField(std::uint64_t seed, std::span<const NoiseOctave> octaves);

  FieldSample sample(double u_cm, double v_cm) const;
  double value(double u_cm, double v_cm) const { return sample(u_cm, v_cm).value; }
  /// Upper bound of |value| (the sum of the amplitudes).
  double bound_cm() const { return bound_cm_; }
  /// Upper bound of |gradient| (dimensionless: cm per cm).
  double slope_bound() const { return slope_bound_; }

 private:
  struct Layer {
    double inv_wavelength = 0.0;
    double amplitude = 0.0;
    double cos_a = 1.0;  ///< lattice rotation
    double sin_a = 0.0;
    double offset_u = 0.0;  ///< lattice shift (lattice units)
    double offset_v = 0.0;
    std::uint64_t seed = 0;
  };
  std::array<Layer, kMaxOctaves> layers_{};
  int count_ = 0;
  double bound_cm_ = 0.0;
  double slope_bound_ = 0.0;
};

}  // namespace minemap::sim
