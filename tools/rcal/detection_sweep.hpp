// The scoring and seeding of `rcal detection-sweep` (cmd_detection_sweep.cpp), apart so that
// tests can check them without running the sweep.
#pragma once

#include <cstdint>
#include <string_view>
#include <vector>

#include "rcal/kinematics/joint_effects.hpp"

namespace rcal::tool {

/// The seed of one cell run: a hash of the effect id, the magnitude (to 1e-6) and the seed
/// index, so that a cell's datasets and its joints are the same whichever other cells run.
std::uint64_t DetectionCellSeed(std::string_view effect_id, double magnitude, unsigned seed_index);

/// A second independent stream derived from a cell seed (stream 1: the joint; 2: the dataset).
std::uint64_t DetectionSubSeed(std::uint64_t cell_seed, unsigned stream);

/// How one analysis scores against the hidden effect.
struct DetectionOutcome {
  bool detected = false;      ///< the hidden cause on its joint (thermal: with its source)
  bool exact = false;         ///< detected with the same harmonic order too (Effect::SameAs)
  bool wrong = false;         ///< effects reported, none the hidden one (wrong cause)
  bool wrong_source = false;  ///< of `wrong`: thermal with the other source (time/temperature)
  bool extra = false;         ///< detected and something else reported too
};
DetectionOutcome ScoreDetection(const kinematics::Effect& hidden,
                                const std::vector<kinematics::Effect>& found);

}  // namespace rcal::tool
