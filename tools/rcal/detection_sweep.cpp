#include "detection_sweep.hpp"

#include <cmath>

namespace rcal::tool {
namespace {

// SplitMix64's finaliser: a bijection of 64-bit words that mixes every bit.
std::uint64_t Mix(std::uint64_t z) {
  z += 0x9e3779b97f4a7c15ull;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

}  // namespace

std::uint64_t DetectionCellSeed(std::string_view effect_id, double magnitude, unsigned seed_index) {
  std::uint64_t h = 0xcbf29ce484222325ull;  // FNV-1a of the id
  for (unsigned char c : effect_id) h = (h ^ c) * 0x100000001b3ull;
  h = Mix(h ^ static_cast<std::uint64_t>(std::llround(magnitude * 1e6)));
  return Mix(h ^ seed_index);
}

std::uint64_t DetectionSubSeed(std::uint64_t cell_seed, unsigned stream) {
  return Mix(cell_seed ^ (0x5851f42d4c957f2dull * stream));
}

DetectionOutcome ScoreDetection(const kinematics::Effect& hidden,
                                const std::vector<kinematics::Effect>& found) {
  using kinematics::EffectCause;
  DetectionOutcome r;
  bool other_source = false;
  for (const auto& e : found) {
    const bool cause = e.cause == hidden.cause && e.joint == hidden.joint;
    const bool source =
        hidden.cause != EffectCause::kThermal || e.thermal_source == hidden.thermal_source;
    r.detected |= cause && source;
    r.exact |= e.SameAs(hidden);
    other_source |= cause && !source;
  }
  r.wrong = !found.empty() && !r.detected;
  r.wrong_source = r.wrong && other_source;
  r.extra = r.detected && found.size() > 1;
  return r;
}

}  // namespace rcal::tool
