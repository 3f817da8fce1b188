#include "rcal/io/imu_csv.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "rcal/io/atomic_file.hpp"
#include "rcal/io/csv_table.hpp"

namespace rcal::io {
namespace {

std::string Number(double v) {
  std::ostringstream o;
  o << v;
  return o.str();
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
      if (std::abs(v(i)) > range)
        Fail(r, c,
             "is " + t_.Text(r, c) + ": beyond the " + sensor + " range ±" + Number(range) + " " +
                 unit + " (ImuCsvSettings::" + setting + ")");
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
  return d;
}

ImuCsv LoadImuCsv(const std::filesystem::path& path, const ImuCsvSettings& settings) {
  return ParseImuCsv(ReadFile(path), path.string(), settings);
}

}  // namespace rcal::io
