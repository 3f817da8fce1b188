// The identifier's checkpoint as a JSON document (schema `rcal.ekf_checkpoint/3`), written
// atomically by the process so that a restart resumes where it stopped. Doubles are written in
// their shortest exact form: Restore(Parse(Text(c))) reproduces the state bit for bit.
// Schema 2 added `held`: the poses held back for the set-up guess before the EKF starts, so a
// restart during the guess phase keeps them. Schema 3 adds `x_fixed` (the values of the
// parameters outside the identified set: the set-up guess the EKF started from) and each
// measurement's `marker` slot. Files of schema 2 (no x_fixed: the identifier's own) and 1 (no
// `held` either) still load. Additive keys (no schema change): the tracking `status`,
// `small_steps`, `inflations`, `second_look_onset` and `second_look_alternatives`, and for an
// extended identifier (ekf_identifier --effects) the `contexts` of its poses and each held pose's
// `context` (temperature_c, payload_kg, time_s: null when unknown; dq_sign), and `effects`: the
// effects of the model the state belongs to, as analysis.json entries (an identifier whose
// discrepancy watch switched effects in resumes with them; absent: the geometric model).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "rcal/cell/online_identification.hpp"
#include "rcal/identification/ekf_identifier.hpp"

namespace rcal::transport {

/// A pose measurement received but not yet given to the EKF (held for the set-up guess).
using HeldPose = cell::TimedPose;

/// A checkpoint and what it belongs to.
struct CheckpointFile {
  std::string model_id;          ///< ModelId() of the model it was taken on
  int64_t utime = 0;             ///< sensor time of the last measurement it includes [µs]
  int64_t last_pose_index = -1;  ///< pose_index of that measurement (−1: none)
  identification::EkfCheckpoint checkpoint;
  std::vector<HeldPose> held;  ///< held back for the set-up guess, oldest first (schema 2)
  /// The effects of the state's model as a JSON array of analysis.json entries
  /// (io::EffectsJson; parse with io::ParseAnalysisEffects against the model); empty: none.
  std::string effects_json = {};
};

/// JSON text of a checkpoint.
std::string CheckpointText(const CheckpointFile& c);
/// Parses CheckpointText output. Throws std::runtime_error naming the key on a malformed file.
CheckpointFile ParseCheckpoint(const std::string& text);

/// Writes atomically (temporary file + rename). Throws std::runtime_error naming the path.
void SaveCheckpoint(const std::filesystem::path& path, const CheckpointFile& c);
/// Reads and parses. Throws std::runtime_error naming the path and the key.
CheckpointFile LoadCheckpoint(const std::filesystem::path& path);

/// "" when every time in `c` (utime and the held poses') is at most `ceiling_us` [µs]; else why
/// not, naming the key. A checkpoint with a far-future time (issue 11: one pose at 2^62 µs made
/// every later pose "out of order", also after a restart) is not to be resumed from.
std::string UntrustedCheckpointTime(const CheckpointFile& c, int64_t ceiling_us);

}  // namespace rcal::transport
