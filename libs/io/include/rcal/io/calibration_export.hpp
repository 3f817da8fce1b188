// An identified model exported with proof (`rcal export`, issue 14 item 4): the calibrated URDF
// (robot_urdf.hpp RobotDescriptionUrdf: world ← base, flange → marker, flange → IMU and earth ←
// world as fixed joints), a YAML of every parameter with its σ (SI units, frames named), and a
// parity report: the written URDF reloaded through liburdfdom (UrdfChain, not ModelBuilder) gives
// the identified model's forward kinematics at seeded random joint vectors within the limits.
//
// Every file carries the calibration hash (CalibrationHash: the model's structure, nominal values
// and the parameter vector), the date, the data the calibration came from, and the σ.
//
// The parameters reach the exporter from a calibration record (schema rcal.calibration/1, the
// `calibration` object `rcal calibrate` writes into its results.json):
//
//   {"schema": "rcal.calibration/1",
//    "robot": "grb3016",                 # the model's name
//    "robot_file": "/abs/path.urdf",     # the robot file (a URDF is reused for the export)
//    "robot_yaml": "schema: rcal.robot/1\n...",  # the robot as fitted, set-up frames included
//    "base_link": "base", "tip_link": "flange",
//    "data": "poses.csv", "date": "2026-12-02T13:00:00Z",
//    "calibration_hash": "fnv1a64:0123456789abcdef",
//    "parameters": [{"name": "a1", "value": 1e-4, "sigma": 2e-6, "identified": true}, ...]}
//                  # every parameter, model order; sigma null: not identified, or unknown
//
// Hostile input (missing keys, wrong types, non-finite values, wrong sizes, parameters of another
// robot) throws std::runtime_error naming the source and the field.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "rcal/io/robot_yaml.hpp"
#include "rcal/kinematics/model.hpp"

namespace rcal::io {

/// "fnv1a64:<16 hex digits>": FNV-1a 64 of the model's name, joints (names, types, limits), every
/// elementary transform (kind, axis, nominal, parameter and joint index), the parameter names and
/// markers, and the bits of x [m, rad]. Equal models at equal x give equal hashes.
std::string CalibrationHash(const kinematics::KinematicModel& model, const Eigen::VectorXd& x);

/// The frame parameter `index` of `model` (BuildModel(spec)) is expressed in, in words:
/// "world ← base (T_WB: ...)", "flange → marker 2 (p_FM, flange frame)", "origin of joint j3
/// (parent link frame)", "link 2 (D–H, previous link frame)".
std::string ParameterFrameText(const RobotSpec& spec, const kinematics::KinematicModel& model,
                               int index);

/// A full parameter vector in model order.
struct ModelParameters {
  Eigen::VectorXd x;      ///< errors from the nominal model [m | rad]
  Eigen::VectorXd sigma;  ///< 1σ [m | rad]; NaN: not identified, or σ unknown (identified)
  /// Which parameters were identified (the others held at their value); empty: those whose σ is
  /// not NaN.
  std::vector<bool> identified;
  bool Identified(int i) const {
    return identified.empty() ? !std::isnan(sigma(i)) : static_cast<bool>(identified.at(i));
  }
};

/// Maps named values onto `model`'s parameters. `sigmas` may be empty (all NaN: none identified);
/// a NaN σ means not identified; a negative or infinite σ is refused, as is a value that is not
/// finite. `identified`, when not empty, says per entry whether it was identified (a NaN σ then
/// means unknown). Every
/// parameter of the model must be named exactly once and no other name may appear (another
/// robot's parameters: "not a parameter of robot M"). `field` names the list in messages, e.g.
/// "results.json: calibration.parameters". Throws std::runtime_error naming the entry.
ModelParameters ParametersByName(const kinematics::KinematicModel& model,
                                 const std::vector<std::string>& names,
                                 const std::vector<double>& values,
                                 const std::vector<double>& sigmas, const std::string& field,
                                 const std::vector<bool>& identified = {});

/// A calibration as `rcal calibrate` records it (schema in the file comment).
struct CalibrationRecord {
  std::string robot;       ///< the model's name
  std::string robot_file;  ///< the robot file it was loaded from
  RobotSpec spec;          ///< the robot as fitted (robot_yaml, base_link, tip_link)
  std::string data;        ///< the data it was fitted to
  std::string date;        ///< ISO 8601 UTC
  std::string calibration_hash;
  std::vector<std::string> names;
  std::vector<double> values, sigmas;  ///< sigmas: NaN for null (not identified or unknown)
  std::vector<bool> identified;        ///< per entry (`identified`; absent: σ not null)
};

/// The record's JSON object. `spec`/`model`/`x`/`sigma` as ExportInput's; hash computed.
nlohmann::json CalibrationRecordJson(const RobotSpec& spec, const kinematics::KinematicModel& model,
                                     const ModelParameters& p, const std::string& robot_file,
                                     const std::string& data, const std::string& date);
/// Parses a record from JSON text: the record itself or a document holding it under
/// `calibration` (a results.json of `rcal calibrate`). Throws std::runtime_error naming `source`
/// and the key; never crashes on any input (fuzz/io/fuzz_calibration_record.cpp).
CalibrationRecord ParseCalibrationRecord(const std::string& text, const std::string& source);

/// What to export: the identified model and where it came from.
struct ExportInput {
  RobotSpec spec;  ///< the robot with its set-up frames (model = BuildModel(spec))
  kinematics::KinematicModel model;  ///< the identified model
  ModelParameters parameters;        ///< its parameter vector and σ
  std::string source_urdf_xml;       ///< the robot's URDF text when it came from one, else empty
  std::string robot_file;            ///< the robot file (for the record)
  std::string data;                  ///< the data the calibration came from
  std::string from;                  ///< the file the parameters were read from
  std::string date;                  ///< ISO 8601 UTC of the calibration; empty: now
};

struct ParityOptions {
  int samples = 1000;                 ///< random joint vectors, uniform within the joint limits
  unsigned seed = 1;                  ///< std::mt19937_64 seed
  double position_tol_m = 1e-9;       ///< largest position difference passed [m]
  double orientation_tol_rad = 1e-9;  ///< largest rotation angle between the two passed [rad]
};

/// One compared frame pair: what the model computes against the URDF chain that should equal it.
struct ParityCheck {
  std::string what;            ///< e.g. "p_WM_W of marker 0: rcal_world -> rcal_marker"
  bool orientation = false;    ///< true: rotation angles [rad]; false: distances [m]
  std::vector<double> errors;  ///< one per joint vector
  double max = 0.0, median = 0.0;
};

struct ParityReport {
  int samples = 0;
  unsigned seed = 0;
  double position_tol_m = 0.0, orientation_tol_rad = 0.0;
  std::vector<ParityCheck> checks;
  double max_position_m = 0.0, median_position_m = 0.0;  ///< over every position check
  double max_orientation_rad = 0.0, median_orientation_rad = 0.0;
  bool passed = false;
};

/// Compares `model` at x with `urdf_xml` loaded through liburdfdom (UrdfChain) at `samples`
/// seeded joint vectors within the limits: each marker's position p_WM_W (rcal_world, or
/// spec.base_link without a base frame, → its rcal_marker link; spec.tip_link without markers),
/// the tool frame's orientation, and R_EI (rcal_earth → rcal_imu) when the model has an IMU or
/// earth frame. Throws std::runtime_error when the URDF lacks a link or its joints are not the
/// model's (a failed parity is a report with passed = false).
ParityReport CheckUrdfParity(const std::string& urdf_xml, const RobotSpec& spec,
                             const kinematics::KinematicModel& model, const Eigen::VectorXd& x,
                             const ParityOptions& options = {});

/// The YAML of every parameter (schema rcal.calibration_parameters/1): name, frame, unit, nominal,
/// error, value = nominal + error, σ (null: not identified) [m, rad], and the calibrated set-up
/// frames with parent and child frame names; a header with the hash, date, data and source.
std::string ParameterYamlText(const ExportInput& in, const std::string& hash,
                              const std::string& date);

/// What ExportCalibration wrote and found.
struct ExportResult {
  std::string hash;
  std::string date;
  ParityReport parity;
  std::vector<std::filesystem::path> files;  ///< in `out_dir`
};

/// Writes, atomically, into `out_dir`: robot_calibrated.urdf, calibration.yaml, calibration.json
/// (the record, ParseCalibrationRecord reads it back), parity.json, parity.md and parity.png (the
/// sorted position and orientation errors; gnuplot). Throws std::runtime_error on a model the
/// parameters do not fit (sizes) or a URDF that cannot be written; a failed parity is returned
/// (parity.passed), the files still written so that the report says what differed.
ExportResult ExportCalibration(const ExportInput& in, const std::filesystem::path& out_dir,
                               const ParityOptions& options = {});

/// The current UTC time as ISO 8601, "2026-12-02T13:00:00Z".
std::string UtcNow();

}  // namespace rcal::io
