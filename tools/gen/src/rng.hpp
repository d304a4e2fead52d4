#pragma once
// Counter-based randomness: every random value is a pure function of (seed, stream, id, counter), so a texture
// looks the same whichever thread paints it and in whatever order (byte-identical output for any --threads).
#include <cmath>
#include <cstdint>

namespace texstream::gen {

// splitmix64's finaliser (Steele, Lea, Flood 2014): a bijective 64-bit mixer with full avalanche.
constexpr uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

constexpr uint64_t hash_combine(uint64_t a, uint64_t b) {
  return mix64(a ^ (b + 0x9e3779b97f4a7c15ull + (a << 6) + (a >> 2)));
}

constexpr uint64_t hash3(uint64_t a, uint64_t b, uint64_t c) { return hash_combine(hash_combine(a, b), c); }

// A uniform float in [0, 1) from the top 24 bits of a hash.
constexpr float unit_float(uint64_t h) { return static_cast<float>(h >> 40) * (1.0f / 16777216.0f); }

// Streams: independent random sequences derived from one seed.
// kOpenLand: the grid cells without a block in the city's ground in pages (city_ground.hpp), by cell.
enum class Stream : uint64_t { kLayout = 1, kBuilding = 2, kTexture = 3, kCamera = 4, kBlock = 5, kOpenLand = 6 };

// A splitmix64 sequence started at hash(seed, stream, id). Cheap to create; one per building or texture.
class Rng {
 public:
  Rng(uint64_t seed, Stream stream, uint64_t id) : state_(hash3(seed, static_cast<uint64_t>(stream), id)) {}

  uint64_t next() {
    state_ += 0x9e3779b97f4a7c15ull;
    return mix64(state_);
  }
  float uniform() { return unit_float(next()); }
  float uniform(float lo, float hi) { return lo + (hi - lo) * uniform(); }
  // Metres and other double quantities: [lo, hi) from 53 random bits.
  double real() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  double real(double lo, double hi) { return lo + (hi - lo) * real(); }
  // An integer in [lo, hi] (inclusive).
  int range(int lo, int hi) { return lo + static_cast<int>(next() % static_cast<uint64_t>(hi - lo + 1)); }
  bool chance(float p) { return uniform() < p; }
  // About exp(N(0, sigma)): the normal deviate is an Irwin-Hall sum of 4 uniforms (bounded, cheap).
  float lognormal_factor(float sigma) {
    const float n = (uniform() + uniform() + uniform() + uniform() - 2.0f) * 1.7320508f;  // unit variance
    return std::exp(sigma * n);
  }

 private:
  uint64_t state_;
};

}  // namespace texstream::gen
