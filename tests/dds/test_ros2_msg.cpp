// deploy/ros2/rcal_msgs/msg/*.msg and services/dds_bridge/idl/rcal_msgs.idl describe the same
// types: the fields of each .msg, mapped the way rosidl maps .msg to IDL, are the fields of the
// IDL struct, in order. And every ROS 2 type of services/dds_bridge/idl/ros2_msgs.idl (what the
// drivers publish and what rcal publishes back: JointState, Imu, TFMessage, ...) matches ROS 2's
// own .msg definition, quoted below field for field, so rmw_cyclonedds nodes and rcal agree on
// the wire.
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

namespace {

using Fields = std::vector<std::pair<std::string, std::string>>;  // (IDL type, name)

std::string Read(const std::string& path) {
  std::ifstream f(path);
  EXPECT_TRUE(f) << path;
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// rosidl's mapping of a .msg field type to IDL.
// A type without a package is the .msg's own package's (`package`).
std::string IdlType(const std::string& ros, const std::string& package) {
  static const std::map<std::string, std::string> kPrimitive = {
      {"float64", "double"}, {"float32", "float"}, {"int32", "int32"},  {"uint32", "uint32"},
      {"int64", "int64"},    {"uint64", "uint64"}, {"bool", "boolean"}, {"string", "string"},
      {"uint8", "uint8"},    {"int8", "int8"},     {"int16", "int16"},  {"uint16", "uint16"},
      {"byte", "octet"},     {"char", "uint8"}};
  if (auto it = kPrimitive.find(ros); it != kPrimitive.end()) return it->second;
  const auto slash = ros.find('/');
  if (slash == std::string::npos) return package + "::msg::dds_::" + ros + "_";
  return ros.substr(0, slash) + "::msg::dds_::" + ros.substr(slash + 1) + "_";
}

// Fields of .msg text as IDL would declare them: "T name" → (T', name), "T[] name" →
// (sequence<T'>, name), "T[N] name" → (T', name[N]). A default value ("float64 w 1") is kept
// out of the wire layout; a constant ("byte OK=0") is not a field.
Fields MsgTextFields(const std::string& text, const std::string& package, const std::string& what) {
  Fields out;
  std::istringstream in(text);
  std::string line;
  const std::regex field(
      R"(^\s*([A-Za-z0-9_/]+)(\[(\d*)\])?\s+([A-Za-z0-9_]+)(\s+[^=\s][^=]*)?\s*$)");
  const std::regex constant(R"(^\s*[A-Za-z0-9_]+\s+[A-Z][A-Z0-9_]*\s*=.*$)");
  while (std::getline(in, line)) {
    line = line.substr(0, line.find('#'));
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    if (std::regex_match(line, constant)) continue;
    std::smatch m;
    EXPECT_TRUE(std::regex_match(line, m, field)) << what << ": cannot read '" << line << "'";
    if (m.empty()) continue;
    const std::string type = IdlType(m[1], package);
    if (!m[2].matched)
      out.emplace_back(type, m[4]);
    else if (m[3].length() == 0)
      out.emplace_back("sequence<" + type + ">", m[4]);
    else
      out.emplace_back(type, std::string(m[4]) + "[" + std::string(m[3]) + "]");
  }
  return out;
}

Fields MsgFields(const std::string& path) {
  return MsgTextFields(Read(path), "rcal_msgs", path);
}

// Fields of `struct name { ... };` in IDL text (comments removed).
Fields IdlFields(const std::string& idl, const std::string& name) {
  std::string text;
  std::istringstream in(idl);
  std::string line;
  while (std::getline(in, line)) text += line.substr(0, line.find("//")) + "\n";
  const std::regex block("struct\\s+" + name + "\\s*\\{([^}]*)\\}");
  std::smatch b;
  if (!std::regex_search(text, b, block)) {
    ADD_FAILURE() << "struct " << name << " not in the IDL";
    return {};
  }
  Fields out;
  const std::string body = b[1];
  const std::regex field(R"(\s*([A-Za-z0-9_:<> ]+?)\s+([A-Za-z0-9_]+(\[\d+\])?)\s*;)");
  for (std::sregex_iterator it(body.begin(), body.end(), field), end; it != end; ++it)
    out.emplace_back((*it)[1], (*it)[2]);
  return out;
}

const std::string kMsgDir = RCAL_SOURCE_DIR "/deploy/ros2/rcal_msgs/msg/";

TEST(Ros2Msg, EveryMsgMatchesItsIdlStruct) {
  const std::string idl = Read(RCAL_DDS_IDL);
  for (const char* type : {"KinematicParams", "CalibrationStatus", "ToolPose"}) {
    SCOPED_TRACE(type);
    const Fields msg = MsgFields(kMsgDir + type + ".msg");
    const Fields dds = IdlFields(idl, std::string(type) + "_");
    ASSERT_FALSE(msg.empty());
    EXPECT_EQ(msg, dds);
    // Every message names its robot, right after the header.
    ASSERT_GE(msg.size(), 2u);
    EXPECT_EQ(msg[0],
              (std::pair<std::string, std::string>{"std_msgs::msg::dds_::Header_", "header"}));
    EXPECT_EQ(msg[1], (std::pair<std::string, std::string>{"string", "robot_id"}));
  }
}

// ROS 2's definitions of the standard types rcal exchanges, as the .msg files of
// ros2/rcl_interfaces (builtin_interfaces), ros2/common_interfaces (std_msgs, geometry_msgs,
// sensor_msgs, diagnostic_msgs) and ros2/geometry2 (tf2_msgs) declare them (comments dropped;
// the same from Humble to Rolling).
struct RosMsg {
  const char* package;
  const char* name;
  const char* text;
};
const RosMsg kRos2Msgs[] = {
    {"builtin_interfaces", "Time", "int32 sec\nuint32 nanosec\n"},
    {"std_msgs", "Header", "builtin_interfaces/Time stamp\nstring frame_id\n"},
    {"std_msgs", "String", "string data\n"},
    {"geometry_msgs", "Vector3", "float64 x\nfloat64 y\nfloat64 z\n"},
    {"geometry_msgs", "Point", "float64 x\nfloat64 y\nfloat64 z\n"},
    {"geometry_msgs", "Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"},
    {"geometry_msgs", "Pose", "Point position\nQuaternion orientation\n"},
    {"geometry_msgs", "PoseStamped", "std_msgs/Header header\nPose pose\n"},
    {"geometry_msgs", "PointStamped", "std_msgs/Header header\nPoint point\n"},
    {"geometry_msgs", "PoseWithCovariance", "Pose pose\nfloat64[36] covariance\n"},
    {"geometry_msgs", "PoseWithCovarianceStamped",
     "std_msgs/Header header\nPoseWithCovariance pose\n"},
    {"geometry_msgs", "Inertia",
     "float64 m\ngeometry_msgs/Vector3 com\nfloat64 ixx\nfloat64 ixy\nfloat64 ixz\nfloat64 iyy\n"
     "float64 iyz\nfloat64 izz\n"},
    {"geometry_msgs", "InertiaStamped", "std_msgs/Header header\nInertia inertia\n"},
    {"geometry_msgs", "Transform", "Vector3 translation\nQuaternion rotation\n"},
    {"geometry_msgs", "TransformStamped",
     "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"},
    {"sensor_msgs", "JointState",
     "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
     "float64[] effort\n"},
    {"sensor_msgs", "Imu",
     "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
     "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
     "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
     "float64[9] linear_acceleration_covariance\n"},
    {"sensor_msgs", "MagneticField",
     "std_msgs/Header header\ngeometry_msgs/Vector3 magnetic_field\n"
     "float64[9] magnetic_field_covariance\n"},
    {"sensor_msgs", "Temperature",
     "std_msgs/Header header\nfloat64 temperature\nfloat64 variance\n"},
    {"tf2_msgs", "TFMessage", "geometry_msgs/TransformStamped[] transforms\n"},
    {"diagnostic_msgs", "KeyValue", "string key\nstring value\n"},
    {"diagnostic_msgs", "DiagnosticStatus",
     "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\n"
     "string message\nstring hardware_id\nKeyValue[] values\n"},
    {"diagnostic_msgs", "DiagnosticArray", "std_msgs/Header header\nDiagnosticStatus[] status\n"},
};

// The body of `module package { module msg { module dds_ { ... } } }` in the IDL (balanced
// braces), so a struct is looked up in its own package only. Empty when that nesting is missing.
std::string ModuleText(const std::string& idl, const std::string& package) {
  const std::regex head("module\\s+" + package +
                        "\\s*\\{\\s*module\\s+msg\\s*\\{\\s*module\\s+dds_\\s*\\{");
  std::smatch m;
  if (!std::regex_search(idl, m, head)) {
    ADD_FAILURE() << "module " << package << "::msg::dds_ not in the IDL";
    return "";
  }
  const size_t begin = static_cast<size_t>(m.position(0) + m.length(0));
  int depth = 1;
  for (size_t i = begin; i < idl.size(); ++i) {
    if (idl[i] == '{') ++depth;
    if (idl[i] == '}' && --depth == 0) return idl.substr(begin, i - begin);
  }
  ADD_FAILURE() << "module " << package << ": unbalanced braces";
  return "";
}

TEST(Ros2Msg, EveryRos2TypeMatchesRos2sDefinition) {
  const std::string idl = Read(RCAL_ROS2_IDL);
  for (const RosMsg& m : kRos2Msgs) {
    SCOPED_TRACE(std::string(m.package) + "/" + m.name);
    const Fields msg = MsgTextFields(m.text, m.package, m.name);
    ASSERT_FALSE(msg.empty());
    EXPECT_EQ(msg, IdlFields(ModuleText(idl, m.package), std::string(m.name) + "_"));
  }
}

TEST(Ros2Msg, RcalMsgsUsesTheRos2TypesNotCopies) {
  // One definition of Time_ and Header_: rcal_msgs.idl includes ros2_msgs.idl.
  const std::string rcal = Read(RCAL_DDS_IDL);
  EXPECT_NE(rcal.find("#include \"ros2_msgs.idl\""), std::string::npos);
  EXPECT_EQ(rcal.find("struct Time_"), std::string::npos);
  EXPECT_EQ(rcal.find("struct Header_"), std::string::npos);
}

TEST(Ros2Msg, PackageBuildsEveryMsg) {
  const std::string cmake = Read(RCAL_SOURCE_DIR "/deploy/ros2/rcal_msgs/CMakeLists.txt");
  for (const char* type : {"KinematicParams", "CalibrationStatus", "ToolPose"})
    EXPECT_NE(cmake.find(std::string("\"msg/") + type + ".msg\""), std::string::npos) << type;
  const std::string package = Read(RCAL_SOURCE_DIR "/deploy/ros2/rcal_msgs/package.xml");
  EXPECT_NE(package.find("<name>rcal_msgs</name>"), std::string::npos);
  EXPECT_NE(package.find("rosidl_interface_packages"), std::string::npos);
}

}  // namespace
