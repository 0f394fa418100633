#pragma once
// Counter-based randomness for the simulator: every random number is a pure function of (seed,
// stream ids, counter), so the survey is bit-identical whatever the thread count or the order in
// which slices are computed. The standard library's distributions are implementation-defined, so
// the conversions to uniform and Gaussian numbers are written out here.
//
// Thread-safety: the free functions are pure; a CounterRng is a small value owned by one thread.
#include <cmath>
#include <cstdint>
#include <numbers>

namespace minemap::sim {

/// SplitMix64's finaliser: a bijective 64-bit mix with full avalanche.
constexpr std::uint64_t mix64(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// Golden-ratio increment (SplitMix64's Weyl step).
inline constexpr std::uint64_t kWeylStep = 0x9e3779b97f4a7c15ULL;

/// A key for one stream: the seed followed by any number of ids (scan index, slice, purpose ...).
constexpr std::uint64_t stream_key(std::uint64_t seed) { return mix64(seed + kWeylStep); }
template <typename... Ids>
constexpr std::uint64_t stream_key(std::uint64_t seed, std::uint64_t id, Ids... ids) {
  return stream_key(mix64(stream_key(seed) ^ mix64(id + 0x632be59bd9b4e019ULL)), static_cast<std::uint64_t>(ids)...);
}

/// Uniform in [0, 1) from the top 53 bits.
constexpr double unit_interval(std::uint64_t bits) { return static_cast<double>(bits >> 11) * 0x1.0p-53; }

/// Purposes of the simulator's streams (part of each key, so streams never collide).
enum class Stream : std::uint64_t {
  kLayout = 1,
  kPillarRow,
  kTimber,
  kRubble,
  kSurfaces,
  kDrive,
  kOdometry,
  kBeam,
  kControl,
};

/// The key of one purpose's stream under a seed, refined by ids.
template <typename... Ids>
constexpr std::uint64_t key_for(std::uint64_t seed, Stream purpose, Ids... ids) {
  return stream_key(seed, static_cast<std::uint64_t>(purpose), static_cast<std::uint64_t>(ids)...);
}

/// A sequential generator over one stream: the n-th draw is mix64(key + n * golden).
class CounterRng {
 public:
  explicit constexpr CounterRng(std::uint64_t key) : key_(key) {}

  constexpr std::uint64_t next_bits() { return mix64(key_ + (++counter_) * kWeylStep); }
  /// Uniform in [0, 1).
  constexpr double uniform() { return unit_interval(next_bits()); }
  /// Uniform in [lo, hi).
  constexpr double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  /// -1 or +1 with equal chance.
  constexpr double sign() { return (next_bits() >> 63) != 0 ? 1.0 : -1.0; }
  /// Uniform integer in [lo, hi].
  int uniform_int(int lo, int hi) {
    const auto span = static_cast<std::uint64_t>(hi - lo) + 1;
    return lo + static_cast<int>(next_bits() % span);
  }
  /// Standard normal (Box-Muller; uses two draws, discards the second variate for simplicity).
  double normal() {
    const double u1 = 1.0 - uniform();  // (0, 1]: log stays finite
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  }

 private:
  std::uint64_t key_;
  std::uint64_t counter_ = 0;
};

}  // namespace minemap::sim
