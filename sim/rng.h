// Seeded random streams of the truth side. Every noise source (one sensor channel, one bias
// random walk) owns one stream seeded from the scenario seed and a stable name, so adding a
// sensor never changes the numbers another sensor draws. Never std::random_device.
//
// The normal deviates are computed here (Box-Muller on 53-bit uniforms) rather than with
// std::normal_distribution, whose algorithm differs between standard libraries: the same seed
// gives the same bytes with any toolchain.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <string>

namespace flexbench::sim {

// FNV-1a 64-bit hash of a name: the stable per-stream id.
inline std::uint64_t StableId(const std::string& name) {
  std::uint64_t h = 14695981039346656037ull;
  for (unsigned char c : name) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

// SplitMix64 finaliser: decorrelates seeds that differ in few bits.
inline std::uint64_t MixSeed(std::uint64_t seed, std::uint64_t stream_id) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (stream_id | 1ull) + stream_id;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

class NoiseStream {
 public:
  NoiseStream() : NoiseStream(0, "") {}
  // `name` identifies the stream (e.g. "link_encoders/j3"); the scenario seed is `seed`.
  NoiseStream(std::uint64_t seed, const std::string& name) : rng_(MixSeed(seed, StableId(name))) {}

  // Uniform in (0, 1), never 0 or 1.
  double Uniform() { return ((rng_() >> 11) + 0.5) * (1.0 / 9007199254740992.0); }

  // Standard normal deviate (Box-Muller; the second deviate of each pair is kept).
  double Normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    const double u1 = Uniform();
    const double u2 = Uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    const double a = 2.0 * M_PI * u2;
    spare_ = r * std::sin(a);
    has_spare_ = true;
    return r * std::cos(a);
  }

  double Normal(double std) { return std > 0.0 ? std * Normal() : 0.0; }

 private:
  std::mt19937_64 rng_;
  bool has_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace flexbench::sim
