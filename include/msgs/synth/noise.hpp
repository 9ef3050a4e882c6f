// include/msgs/synth/noise.hpp
// Deterministic randomness for the synthetic scene generator: counter-based hashing, a small
// generator with a portable normal distribution, and seeded value noise / fBm for procedural textures.
#pragma once

#include <cmath>
#include <cstdint>

namespace msgs::synth {

/// SplitMix64 finaliser: a bijective 64-bit mix, the basis of every random number here. The
/// standard library distributions are implementation-defined, so they would make files differ
/// between toolchains; everything below is written out.
constexpr std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

/// Hash of a seed and a value; chaining calls hashes a tuple (seed, a, b, ...).
constexpr std::uint64_t hash_mix(std::uint64_t seed, std::uint64_t v) {
  return splitmix64(seed ^ splitmix64(v + 0x632be59bd9b4e019ULL));
}

/// Hash of a tuple of integers.
template <class... Ts>
constexpr std::uint64_t hash_tuple(std::uint64_t seed, Ts... vs) {
  ((seed = hash_mix(seed, static_cast<std::uint64_t>(static_cast<std::int64_t>(vs)))), ...);
  return seed;
}

/// Top 24 bits of a hash as a float in [0, 1): exactly representable, so identical everywhere.
constexpr float hash_to_unit(std::uint64_t h) { return float(h >> 40) * (1.0f / 16777216.0f); }

/// Sequential generator (SplitMix64 stream) for the few places that need many draws in order.
struct Rng {
  std::uint64_t state;
  explicit Rng(std::uint64_t seed) : state(splitmix64(seed)) {}
  std::uint64_t next() { state += 0x9e3779b97f4a7c15ULL; return splitmix64(state); }
  /// Uniform in [0, 1) with 53 bits.
  double uniform() { return double(next() >> 11) * (1.0 / 9007199254740992.0); }
  /// Uniform in [a, b).
  double uniform(double a, double b) { return a + (b - a) * uniform(); }
  /// Uniform integer in [0, n).
  std::uint64_t below(std::uint64_t n) { return n == 0 ? 0 : next() % n; }
  /// Standard normal by Box-Muller (one value per call; simple beats fast here).
  double normal() {
    const double u1 = 1.0 - uniform();  // (0, 1], keeps log finite
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(6.283185307179586 * u2);
  }
};

namespace detail {
inline float smooth5(float t) { return t * t * t * (t * (t * 6.f - 15.f) + 10.f); }
inline float lerp(float a, float b, float t) { return a + (b - a) * t; }
inline float lattice(std::uint64_t seed, std::int64_t i, std::int64_t j, std::int64_t k) {
  return hash_to_unit(hash_tuple(seed, i, j, k));
}
}  // namespace detail

/// 3-D value noise in [0, 1): random values on the integer lattice, quintic interpolation.
inline float value_noise(float x, float y, float z, std::uint64_t seed) {
  const float fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
  const auto i = static_cast<std::int64_t>(fx), j = static_cast<std::int64_t>(fy), k = static_cast<std::int64_t>(fz);
  const float u = detail::smooth5(x - fx), v = detail::smooth5(y - fy), w = detail::smooth5(z - fz);
  using detail::lattice;
  using detail::lerp;
  const float x00 = lerp(lattice(seed, i, j, k), lattice(seed, i + 1, j, k), u);
  const float x10 = lerp(lattice(seed, i, j + 1, k), lattice(seed, i + 1, j + 1, k), u);
  const float x01 = lerp(lattice(seed, i, j, k + 1), lattice(seed, i + 1, j, k + 1), u);
  const float x11 = lerp(lattice(seed, i, j + 1, k + 1), lattice(seed, i + 1, j + 1, k + 1), u);
  return lerp(lerp(x00, x10, v), lerp(x01, x11, v), w);
}

/// 2-D value noise in [0, 1) (the z = 0 slice of the 3-D one).
inline float value_noise(float x, float y, std::uint64_t seed) {
  const float fx = std::floor(x), fy = std::floor(y);
  const auto i = static_cast<std::int64_t>(fx), j = static_cast<std::int64_t>(fy);
  const float u = detail::smooth5(x - fx), v = detail::smooth5(y - fy);
  using detail::lattice;
  using detail::lerp;
  return lerp(lerp(lattice(seed, i, j, 0), lattice(seed, i + 1, j, 0), u),
              lerp(lattice(seed, i, j + 1, 0), lattice(seed, i + 1, j + 1, 0), u), v);
}

/// Fractal sum of `octaves` 2-D value noises (lacunarity 2, gain 0.5), normalised to [0, 1).
inline float fbm(float x, float y, int octaves, std::uint64_t seed) {
  float sum = 0.f, amp = 1.f, norm = 0.f;
  for (int o = 0; o < octaves; ++o) {
    sum += amp * value_noise(x, y, hash_mix(seed, std::uint64_t(o)));
    norm += amp;
    amp *= 0.5f;
    // Rotate-free octaves would align their lattices; a fixed irrational shift avoids it.
    x = 2.f * x + 0.3183f;
    y = 2.f * y + 0.5772f;
  }
  return sum / norm;
}

/// Fractal sum of `octaves` 3-D value noises, normalised to [0, 1).
inline float fbm(float x, float y, float z, int octaves, std::uint64_t seed) {
  float sum = 0.f, amp = 1.f, norm = 0.f;
  for (int o = 0; o < octaves; ++o) {
    sum += amp * value_noise(x, y, z, hash_mix(seed, std::uint64_t(o)));
    norm += amp;
    amp *= 0.5f;
    x = 2.f * x + 0.3183f;
    y = 2.f * y + 0.5772f;
    z = 2.f * z + 0.1415f;
  }
  return sum / norm;
}

/// Hermite step between edges a < b, clamped to [0, 1].
inline float smoothstep(float a, float b, float x) {
  float t = (x - a) / (b - a);
  t = t < 0.f ? 0.f : (t > 1.f ? 1.f : t);
  return t * t * (3.f - 2.f * t);
}

}  // namespace msgs::synth
