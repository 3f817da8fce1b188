#include "rcal/io/imu_csv.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "rcal/io/atomic_file.hpp"
#include "rcal/io/csv_table.hpp"
#include "rcal/numeric/median.hpp"

namespace rcal::io {
namespace {

std::string Number(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
}

constexpr double kG = 9.80665;  // standard gravity [m/s²]
// Earth's field at its surface [µT]: 22 (South Atlantic anomaly) to 67 (near the poles).
constexpr double kEarthFieldMinUt = 22.0, kEarthFieldMaxUt = 67.0;
// How far a stream's median may lie from those before no unit explains it: a factor of 3 either
// way. An accelerometer leaves [g/3, 3g] in most of its samples only while accelerating at more
// than 2g for more than half the recording; a magnetometer reads the Earth's field times a
// factor of 3 in most of its samples only inside a magnet's field for more than half of it.
constexpr double kMedianFactor = 3.0;

/// What a whole stream says about its units: the median specific force and field magnitudes, and
/// the rate the gyro reads against the rate the magnetic field turns in the IMU frame. A field
/// fixed in the earth frame turns in the IMU frame as du/dt = −ω × u (u = m/|m|), so over the
/// stream Δu ≈ −s·(ω × u)·Δt with s = 1 when the gyro reads rad/s and π/180 when it reads °/s.
/// s by least squares over consecutive samples, with its standard error (the BROAD trials: s =
/// 0.90 … 1.09, with magnets near or on the IMU too). Rows that fail to parse are left out.
struct StreamUnits {
  double accel_median = std::nan("");  // median |acc| as written
  double mag_median = std::nan("");    // median |mag| as written
  double gyro_scale = std::nan("");    // s
  double gyro_scale_se = std::nan("");
};

StreamUnits ReadUnits(const CsvTable& t) {
  StreamUnits u;
  std::vector<double> time, acc, mag;
  std::vector<Eigen::Vector3d> gyro, field;
  for (int r = 0; r < t.rows(); ++r) {
    try {
      Eigen::Vector3d g, a, m;
      for (int i = 0; i < 3; ++i) {
        g(i) = t.At(r, std::string("gyr_") + "xyz"[i]);
        a(i) = t.At(r, std::string("acc_") + "xyz"[i]);
        m(i) = t.At(r, std::string("mag_") + "xyz"[i]);
      }
      const double ts = t.At(r, "t_s");
      if (!std::isfinite(ts) || !g.allFinite() || !a.allFinite() || !m.allFinite()) continue;
      acc.push_back(a.norm());
      mag.push_back(m.norm());
      time.push_back(ts);
      gyro.push_back(g);
      field.push_back(m);
    } catch (const std::exception&) {
    }
  }
  u.accel_median = numeric::UpperMedian(acc);
  u.mag_median = numeric::UpperMedian(mag);
  // Least squares of Δu = s·p, p = −(ω̄ × ū)·Δt, over consecutive rows.
  double pp = 0, pd = 0, dd = 0;
  int n = 0;
  for (size_t k = 0; k + 1 < time.size(); ++k) {
    const double dt = time[k + 1] - time[k];
    const double n0 = field[k].norm(), n1 = field[k + 1].norm();
    if (!(dt > 0) || n0 == 0 || n1 == 0) continue;
    const Eigen::Vector3d u0 = field[k] / n0, u1 = field[k + 1] / n1;
    const Eigen::Vector3d p = -(0.5 * (gyro[k] + gyro[k + 1])).cross(0.5 * (u0 + u1)) * dt;
    const Eigen::Vector3d d = u1 - u0;
    pp += p.squaredNorm();
    pd += p.dot(d);
    dd += d.squaredNorm();
    n += 3;
  }
  if (pp > 0 && n > 1 && std::isfinite(pp)) {
    u.gyro_scale = pd / pp;
    const double residual = std::max(0.0, dd - pd * pd / pp);  // Σ|d − s·p|²
    u.gyro_scale_se = std::sqrt(residual / (n - 1) / pp);
  }
  return u;
}

/// "degrees per second?": the field turns at about π/180 of the rate the gyro reads, within the
/// band where π/180 is the nearer of 1 and π/180 on a log scale (π/180 ×÷ √(180/π): 0.0023 …
/// 0.13), by three standard errors. A stream with too little rotation to tell, or whose field
/// does not turn with the gyro at all (s ≈ 0: a gyro bias, a synthetic stream), says nothing.
std::string GyroHint(const StreamUnits& u) {
  const double deg = std::numbers::pi / 180.0, spread = std::sqrt(180.0 / std::numbers::pi);
  if (!(u.gyro_scale - 3.0 * u.gyro_scale_se > deg / spread &&
        u.gyro_scale + 3.0 * u.gyro_scale_se < deg * spread))
    return "";
  return "the magnetic field turns in the IMU frame at " + Number(u.gyro_scale) + " ± " +
         Number(u.gyro_scale_se) +
         " of the rate the gyro reads (1 in rad/s, π/180 = 0.01745 in °/s): gyro in degrees per "
         "second? rcal reads rad/s";
}

/// The unit that puts `median` × factor within the factor of 3 of [lo, hi], or "".
std::string UnitFor(double median, double lo, double hi,
                    std::initializer_list<std::pair<const char*, double>> units) {
  for (const auto& [name, factor] : units) {
    const double v = median * factor;
    if (v >= lo / kMedianFactor && v <= hi * kMedianFactor)
      return std::string(name) + " (× " + Number(factor) + ")";
  }
  return "";
}

std::string AccelHint(const StreamUnits& u) {
  const double m = u.accel_median;
  if (!std::isfinite(m) || (m >= kG / kMedianFactor && m <= kG * kMedianFactor)) return "";
  const std::string unit = UnitFor(m, kG, kG, {{"g", kG}, {"milli-g", kG * 1e-3}});
  return "the median |acc| is " + Number(m) + ", where an accelerometer on Earth reads " +
         Number(kG) + " m/s² at rest (refused outside " + Number(kG / kMedianFactor) + " … " +
         Number(kG * kMedianFactor) + " m/s²)" +
         (unit.empty() ? ": is it an accelerometer in m/s²?"
                       : ": accelerometer in " + unit + "? rcal reads m/s²");
}

std::string MagHint(const StreamUnits& u) {
  const double m = u.mag_median;
  // All zero: a stream without magnetometer, not a unit; the filters' settings decide.
  if (!std::isfinite(m) || m == 0.0 ||
      (m >= kEarthFieldMinUt / kMedianFactor && m <= kEarthFieldMaxUt * kMedianFactor))
    return "";
  const std::string unit =
      UnitFor(m, kEarthFieldMinUt, kEarthFieldMaxUt,
              {{"tesla", 1e6}, {"gauss", 100.0}, {"milligauss", 0.1}, {"nanotesla", 1e-3}});
  return "the median |mag| is " + Number(m) + ", where Earth's field is " +
         Number(kEarthFieldMinUt) + " … " + Number(kEarthFieldMaxUt) + " µT (refused outside " +
         Number(kEarthFieldMinUt / kMedianFactor) + " … " +
         Number(kEarthFieldMaxUt * kMedianFactor) + " µT)" +
         (unit.empty() ? ": is it a magnetometer in µT?"
                       : ": magnetometer in " + unit + "? rcal reads µT");
}

class Rows {
 public:
  explicit Rows(const CsvTable& t) : t_(t) {}

  [[noreturn]] void Fail(int r, const std::string& column, const std::string& what) const {
    throw std::runtime_error(t_.source() + ": row " + std::to_string(r + 1) + " column '" + column +
                             "' " + what);
  }

  /// A finite cell.
  double Finite(int r, const std::string& column) const {
    const double v = t_.At(r, column);  // throws naming row and column for text
    if (!std::isfinite(v))
      Fail(r, column,
           "is " + (t_.Text(r, column).empty() ? std::string("empty") : t_.Text(r, column)) +
               ": a finite number is required");
    return v;
  }

  /// Three finite cells PREFIX_x, _y, _z, each within ±range.
  Eigen::Vector3d Sensor(int r, const std::string& prefix, double range, const char* sensor,
                         const char* unit, const char* setting) const {
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) {
      const std::string c = prefix + "xyz"[i];
      v(i) = Finite(r, c);
      if (std::abs(v(i)) > range) {
        // The likely unit mistake of the whole stream, when it shows one.
        const StreamUnits u = ReadUnits(t_);
        const std::string hint = prefix == "gyr_"   ? GyroHint(u)
                                 : prefix == "acc_" ? AccelHint(u)
                                                    : MagHint(u);
        Fail(r, c,
             "is " + t_.Text(r, c) + ": beyond the " + sensor + " range ±" + Number(range) + " " +
                 unit + " (ImuCsvSettings::" + setting + ")" + (hint.empty() ? "" : "; " + hint));
      }
    }
    return v;
  }

 private:
  const CsvTable& t_;
};

}  // namespace

ImuCsv ParseImuCsv(const std::string& text, const std::string& source,
                   const ImuCsvSettings& settings) {
  const CsvTable t = CsvTable::Parse(text, source);
  for (const char* c :
       {"t_s", "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z", "mag_x", "mag_y", "mag_z"})
    if (!t.Has(c)) throw std::runtime_error(source + ": missing column '" + c + "'");
  auto group = [&](const char* what, std::initializer_list<const char*> cols) {
    int n = 0;
    for (const char* c : cols) n += t.Has(c) ? 1 : 0;
    if (n != 0 && n != static_cast<int>(cols.size()))
      throw std::runtime_error(source + ": columns " + what + " come together: some are missing");
    return n != 0;
  };
  ImuCsv d;
  d.has_truth = group("'q_w,q_x,q_y,q_z'", {"q_w", "q_x", "q_y", "q_z"});
  d.has_position = group("'pos_x,pos_y,pos_z'", {"pos_x", "pos_y", "pos_z"});
  d.has_movement = t.Has("movement");
  if (t.rows() == 0) throw std::runtime_error(source + ": no samples");
  const Rows rows(t);
  const double nan = std::nan("");
  for (int r = 0; r < t.rows(); ++r) {
    const double time = rows.Finite(r, "t_s");
    if (!d.t.empty() && !(time > d.t.back()))
      rows.Fail(r, "t_s",
                "is " + t.Text(r, "t_s") + ": time must increase (previous row " +
                    Number(d.t.back()) + " s)");
    d.t.push_back(time);
    d.gyro.push_back(
        rows.Sensor(r, "gyr_", settings.gyro_range_rad_s, "gyro", "rad/s", "gyro_range_rad_s"));
    d.accel.push_back(rows.Sensor(r, "acc_", settings.accel_range_m_s2, "accelerometer", "m/s²",
                                  "accel_range_m_s2"));
    d.mag_uT.push_back(
        rows.Sensor(r, "mag_", settings.mag_range_uT, "magnetometer", "µT", "mag_range_uT"));
    if (d.has_truth) {
      const char* cols[4] = {"q_w", "q_x", "q_y", "q_z"};
      Eigen::Vector4d q;
      int present = 0;
      for (int i = 0; i < 4; ++i) {
        q(i) = t.At(r, cols[i]);
        present += std::isnan(q(i)) ? 0 : 1;
      }
      if (present == 0) {
        ++d.truth_missing;
        d.q_truth.emplace_back(nan, nan, nan, nan);
      } else {
        for (int i = 0; i < 4; ++i)
          if (!std::isfinite(q(i)))
            rows.Fail(r, cols[i],
                      "is " + t.Text(r, cols[i]) +
                          ": a truth quaternion is all four numbers or all four NaN");
        const double norm = q.norm();
        if (!(std::abs(norm - 1.0) <= settings.quaternion_tolerance))
          rows.Fail(r, "q_w",
                    "starts a quaternion of norm " + Number(norm) +
                        ": not a unit quaternion (ImuCsvSettings::quaternion_tolerance)");
        d.q_truth.push_back(q / norm);
      }
    }
    if (d.has_position) {
      Eigen::Vector3d p;
      for (int i = 0; i < 3; ++i) {
        const std::string c = std::string("pos_") + "xyz"[i];
        p(i) = t.At(r, c);
        if (std::isinf(p(i)) || std::abs(p(i)) > settings.position_range_m)
          rows.Fail(r, c,
                    "is " + t.Text(r, c) + ": beyond ±" + Number(settings.position_range_m) +
                        " m (ImuCsvSettings::position_range_m)");
      }
      if (!p.allFinite()) {
        ++d.position_missing;
        p.setConstant(nan);
      }
      d.p_truth.push_back(p);
    }
    if (d.has_movement) {
      const double m = t.At(r, "movement");
      if (m != 0.0 && m != 1.0)
        rows.Fail(
            r, "movement",
            "is " + (t.Text(r, "movement").empty() ? std::string("empty") : t.Text(r, "movement")) +
                ": must be 0 or 1");
      d.movement.push_back(static_cast<int>(m));
    }
  }
  // Units the ranges cannot see: a gyro in °/s below 35, an accelerometer in g, a magnetometer
  // in tesla or gauss.
  if (settings.check_units) {
    const StreamUnits u = ReadUnits(t);
    for (const auto& [columns, hint] :
         {std::pair<const char*, std::string>{"gyr_x,gyr_y,gyr_z", GyroHint(u)},
          {"acc_x,acc_y,acc_z", AccelHint(u)},
          {"mag_x,mag_y,mag_z", MagHint(u)}})
      if (!hint.empty())
        throw std::runtime_error(source + ": columns '" + columns + "': " + hint +
                                 " (ImuCsvSettings::check_units)");
  }
  return d;
}

ImuCsv LoadImuCsv(const std::filesystem::path& path, const ImuCsvSettings& settings) {
  return ParseImuCsv(ReadFile(path), path.string(), settings);
}

double SampleRate(const ImuCsv& stream) {
  std::vector<double> steps;
  steps.reserve(stream.t.size());
  for (std::size_t k = 1; k < stream.t.size(); ++k) steps.push_back(stream.t[k] - stream.t[k - 1]);
  // The parser has checked the time strictly increasing and finite: every step is positive.
  return 1.0 / numeric::Median(std::move(steps));
}

}  // namespace rcal::io
