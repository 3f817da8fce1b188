// The YAML reading shared by rcal's own configuration parsers (robot_yaml.cpp: rcal.robot/1,
// cell_yaml.cpp: rcal.cell/1, libs/cell's cell_sim_yaml.cpp: rcal.cell_sim/1). Not an API for
// users: namespace detail, and it may change with those files.
//
// Every accessor knows the file and the key path, so every error names both:
//   "SOURCE: KEY.PATH: what is wrong (line N)"
// Numbers are plain decimals (YAML's .nan/.inf spellings are recognised only to be refused as not
// finite); they never carry units (rcal files are SI).
#pragma once

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>

#include "rcal/io/robot_yaml.hpp"

namespace rcal::io::detail {

/// Bounds of every length [m] and angle [rad] read by Reader::Number (robot_yaml.hpp).
inline constexpr double kMaxLength = 100.0;
inline constexpr double kMaxAngle = 100.0;

/// YAML's spellings of the non-finite numbers (.nan, .inf, -.Inf, ...), or nullopt.
inline std::optional<double> YamlSpecial(const std::string& s) {
  std::string t = s;
  double sign = 1.0;
  if (!t.empty() && (t[0] == '-' || t[0] == '+')) {
    sign = t[0] == '-' ? -1.0 : 1.0;
    t.erase(0, 1);
  }
  for (const char* nan : {".nan", ".NaN", ".NAN"})
    if (t == nan) return std::numeric_limits<double>::quiet_NaN();
  for (const char* inf : {".inf", ".Inf", ".INF"})
    if (t == inf) return sign * std::numeric_limits<double>::infinity();
  return std::nullopt;
}

/// A plain decimal number (optional leading '+'), the whole text, or nullopt.
inline std::optional<double> PlainNumber(const std::string& s) {
  double d = 0;
  const char* first = s.data();
  const char* last = s.data() + s.size();
  if (first != last && *first == '+') ++first;
  const auto [ptr, ec] = std::from_chars(first, last, d);
  if (ec == std::errc() && ptr == last && first != last) return d;
  return std::nullopt;
}

/// Parses YAML text; malformed YAML and an empty document are errors naming `source`.
inline YAML::Node LoadYaml(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw std::runtime_error(source + ": malformed YAML: " + e.msg + " (line " +
                             std::to_string(e.mark.line + 1) + ", column " +
                             std::to_string(e.mark.column + 1) + ")");
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(source + ": malformed YAML: " + e.what());
  }
  if (!root.IsDefined() || root.IsNull()) throw std::runtime_error(source + ": empty file");
  return root;
}

class Reader {
 public:
  /// `kind` names the files in the hint given for a top-level `units:` key ("robot files").
  explicit Reader(std::string source, std::string kind = "robot files")
      : source_(std::move(source)), kind_(std::move(kind)) {}

  [[noreturn]] void Fail(const std::string& path, const std::string& what,
                         const YAML::Node* node = nullptr) const {
    std::string msg = source_ + ": " + (path.empty() ? std::string("<top>") : path) + ": " + what;
    if (node != nullptr && node->IsDefined()) {
      const YAML::Mark m = node->Mark();
      if (m.line >= 0) msg += " (line " + std::to_string(m.line + 1) + ")";
    }
    throw std::runtime_error(msg);
  }

  /// Fail at a node that is a temporary (map[key], list[i]).
  [[noreturn]] void FailAt(const std::string& path, const std::string& what,
                           const YAML::Node& node) const {
    Fail(path, what, &node);
  }

  /// The node must be a map whose keys are all in `allowed`, each at most once.
  void CheckMap(const YAML::Node& node, const std::string& path,
                const std::set<std::string>& allowed) const {
    if (!node.IsMap()) Fail(path, "expected a map (key: value ...), got " + Kind(node), &node);
    std::set<std::string> seen;
    for (auto it = node.begin(); it != node.end(); ++it) {
      if (!it->first.IsScalar()) Fail(path, "keys must be plain words", &it->first);
      const std::string key = it->first.Scalar();
      const std::string sub = Join(path, key);
      if (!seen.insert(key).second) Fail(sub, "duplicate key", &it->first);
      if (!allowed.count(key)) {
        if (path.empty() && key == "units")
          Fail(sub, "unknown key (" + kind_ + " are SI only: m, rad; there is no units setting)",
               &it->first);
        Fail(sub, "unknown key", &it->first);
      }
    }
  }

  static std::string Join(const std::string& path, const std::string& key) {
    return path.empty() ? key : path + "." + key;
  }

  YAML::Node Require(const YAML::Node& map, const std::string& path, const std::string& key) const {
    const YAML::Node n = map[key];
    if (!n.IsDefined()) Fail(Join(path, key), "missing key", &map);
    return n;
  }

  std::string String(const YAML::Node& n, const std::string& path) const {
    if (!n.IsScalar() || n.Scalar().empty()) Fail(path, "expected a text, got " + Kind(n), &n);
    return n.Scalar();
  }

  bool Bool(const YAML::Node& n, const std::string& path) const {
    if (n.IsScalar()) {
      if (n.Scalar() == "true") return true;
      if (n.Scalar() == "false") return false;
    }
    Fail(path, "expected true or false, got " + Kind(n), &n);
  }

  /// A length [m] (plain number) or, with `angle`, an angle [rad] (number or multiple of pi),
  /// within kMaxLength or kMaxAngle.
  double Number(const YAML::Node& n, const std::string& path, bool angle) const {
    const double v = Parse(n, path, angle);
    const std::string& s = n.Scalar();
    // Beyond the bound, the likely unit when it gives a value within it: millimetres (a 600 mm
    // link as 600 m), degrees up to two turns (a limit of 170° as 170 rad).
    if (!angle && std::abs(v) > kMaxLength)
      Fail(path,
           "'" + s + "' is beyond 100 m: not an arm's dimension" +
               (std::abs(v) * 1e-3 <= kMaxLength ? ": millimetres? rcal files are in metres" : ""),
           &n);
    if (angle && std::abs(v) > kMaxAngle)
      Fail(path,
           "'" + s + "' is beyond 100 rad" +
               (std::abs(v) <= 720.0 ? ": degrees? rcal files are in radians (a number or a "
                                       "multiple of pi such as -pi/2)"
                                     : ""),
           &n);
    return v;
  }

  /// An angle [rad] within ±`bound` (1e-3 rad of rounding allowed: 6.2832 for 2π); `bound_text`
  /// names the bound in the message ("a turn (2π)"). Beyond it, when the value read as degrees
  /// lies within the bound: "degrees?" and the value in radians ("-90° is -pi/2"). A robot's
  /// constant angles are within a turn and its joint limits within two: an angle written in
  /// degrees (alpha: -90, upper: 170) is beyond them.
  double BoundedAngle(const YAML::Node& n, const std::string& path, double bound,
                      const std::string& bound_text) const {
    const double v = Parse(n, path, true);
    if (std::abs(v) <= bound + kAngleRounding) return v;
    Fail(path, "'" + n.Scalar() + "' rad is beyond " + bound_text + DegreesHint(v, bound), &n);
  }

  /// ": degrees? rcal files are in radians: 170° is 17*pi/18" when `value` read as degrees lies
  /// within ±bound [rad], else empty.
  static std::string DegreesHint(double value, double bound) {
    if (!(std::abs(value) * std::numbers::pi / 180.0 <= bound + kAngleRounding)) return "";
    return ": degrees? rcal files are in radians: " + ShortText(value) + "° is " +
           DegreesAsRadians(value);
  }

  /// Degrees as radians in a robot file's words: a multiple of pi when exact ("-pi/2",
  /// "17*pi/18"), else the number to 6 digits.
  static std::string DegreesAsRadians(double degrees) {
    for (const int q : {1, 2, 3, 4, 6, 9, 12, 18, 36, 180}) {
      const double p = degrees * q / 180.0;
      if (std::abs(p - std::round(p)) > 1e-9) continue;
      const long long k = std::llround(p);
      if (k == 0) return "0";
      const std::string num = k == 1 ? "pi" : k == -1 ? "-pi" : std::to_string(k) + "*pi";
      return q == 1 ? num : num + "/" + std::to_string(q);
    }
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%.6g", degrees * std::numbers::pi / 180.0);
    return buf;
  }

  Eigen::Vector3d Vec3(const YAML::Node& n, const std::string& path, bool angle) const {
    if (!n.IsSequence() || n.size() != 3)
      Fail(path, "expected a list of 3 numbers [x, y, z], got " + Kind(n), &n);
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) v(i) = Number(n[i], path + "[" + std::to_string(i) + "]", angle);
    return v;
  }

  /// A finite plain number in `unit` (named in messages, e.g. "Hz"), no bound. A number followed
  /// by a unit ("100 Hz", "5mm") is refused: files are SI and numbers carry no units.
  double Quantity(const YAML::Node& n, const std::string& path, const std::string& unit) const {
    if (!n.IsScalar() || n.Scalar().empty())
      Fail(path, "expected a number [" + unit + "], got " + Kind(n), &n);
    const std::string& s = n.Scalar();
    std::optional<double> v = YamlSpecial(s);
    if (!v) v = PlainNumber(s);
    if (!v) {
      // A leading number with letters after it: a unit written into the value.
      double d = 0;
      const char* first = s.data() + (s[0] == '+' ? 1 : 0);
      const auto [ptr, ec] = std::from_chars(first, s.data() + s.size(), d);
      if (ec == std::errc() && ptr != first)
        Fail(path,
             "expected a number [" + unit + "], got '" + s +
                 "': numbers carry no units (write the value in " + unit + ")",
             &n);
      Fail(path, "expected a number [" + unit + "], got '" + s + "'", &n);
    }
    if (!std::isfinite(*v)) Fail(path, "value is not finite: '" + s + "'", &n);
    return *v;
  }

  /// An integer in [lo, hi] (no fraction, no exponent).
  long long Integer(const YAML::Node& n, const std::string& path, long long lo,
                    long long hi) const {
    const std::string text = n.IsScalar() ? n.Scalar() : std::string();
    long long v = 0;
    const char* first = text.data() + (!text.empty() && text[0] == '+' ? 1 : 0);
    const char* last = text.data() + text.size();
    const auto [end, ec] = std::from_chars(first, last, v);
    if (text.empty() || first == last || ec != std::errc() || end != last || v < lo || v > hi)
      Fail(path,
           "expected an integer from " + std::to_string(lo) + " to " + std::to_string(hi) +
               ", got " + (n.IsScalar() ? "'" + text + "'" : Kind(n)),
           &n);
    return v;
  }

  static std::string Kind(const YAML::Node& n) {
    if (!n.IsDefined() || n.IsNull()) return "nothing";
    if (n.IsScalar()) return "'" + n.Scalar() + "'";
    if (n.IsSequence()) return "a list of " + std::to_string(n.size());
    if (n.IsMap()) return "a map";
    return "something else";
  }

  const std::string& source() const { return source_; }

 private:
  /// Rounding allowed beyond an angle bound [rad] (6.2832 written for 2π).
  static constexpr double kAngleRounding = 1e-3;

  /// A finite length (plain number) or angle (number or multiple of pi), no bound.
  double Parse(const YAML::Node& n, const std::string& path, bool angle) const {
    if (!n.IsScalar() || n.Scalar().empty())
      Fail(path,
           std::string("expected ") + (angle ? "an angle [rad]" : "a number") + ", got " + Kind(n),
           &n);
    const std::string& s = n.Scalar();
    std::optional<double> v = YamlSpecial(s);
    if (v) {
      // .nan / .inf: reported as not finite below
    } else if (angle) {
      v = ParseAngle(s);
    } else {
      v = PlainNumber(s);
    }
    if (!v) {
      if (!angle && ParseAngle(s))
        Fail(path, "expected a number [m], got '" + s + "' (pi is for angles only)", &n);
      Fail(
          path,
          std::string("expected ") +
              (angle ? "an angle [rad] (a number or a multiple of pi such as -pi/2)" : "a number") +
              ", got '" + s + "'",
          &n);
    }
    if (!std::isfinite(*v)) Fail(path, "value is not finite: '" + s + "'", &n);
    return *v;
  }

  /// The shortest text of a number that reads back the same.
  static std::string ShortText(double v) {
    char buf[64];
    const auto [ptr, ec] = std::to_chars(buf, buf + sizeof(buf), v);
    return ec == std::errc() ? std::string(buf, ptr) : std::to_string(v);
  }

  std::string source_;
  std::string kind_;
};

/// Shortest text of a number that reads back the same ("0.05", "1e+09").
/// The shortest text of a number that reads back the same ("0.05", "1e+09"), for messages.
inline std::string ShortNumber(double v) {
  char buf[64];
  const auto [ptr, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  return ec == std::errc() ? std::string(buf, ptr) : std::to_string(v);
}

/// Reads a number in `unit` and checks lo ≤ v ≤ hi (lo_open: lo < v). Beyond hi, `above` (when
/// not empty) names the likely unit mistake; below lo, `below` does.
inline double Bounded(const Reader& r, const YAML::Node& n, const std::string& path,
                      const std::string& unit, double lo, double hi, const std::string& above = "",
                      const std::string& below = "", bool lo_open = false) {
  const double v = r.Quantity(n, path, unit);
  const std::string u = unit == "-" ? "" : " " + unit;
  if (v > hi)
    r.Fail(path,
           ShortNumber(v) + u + " is beyond " + ShortNumber(hi) + u +
               (above.empty() ? "" : ": " + above),
           &n);
  if (v < lo || (lo_open && v == lo))
    r.Fail(path,
           ShortNumber(v) + u + " is " + (lo_open ? "not above " : "below ") + ShortNumber(lo) + u +
               (below.empty() ? "" : ": " + below),
           &n);
  return v;
}

}  // namespace rcal::io::detail
