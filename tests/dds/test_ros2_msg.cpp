// deploy/ros2/rcal_msgs/msg/*.msg and services/dds_bridge/idl/rcal_msgs.idl describe the same
// types: the fields of each .msg, mapped the way rosidl maps .msg to IDL, are the fields of the
// IDL struct, in order. Also the builtin types the IDL repeats match ROS 2's own definitions.
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
std::string IdlType(const std::string& ros) {
  static const std::map<std::string, std::string> kPrimitive = {
      {"float64", "double"}, {"float32", "float"}, {"int32", "int32"},  {"uint32", "uint32"},
      {"int64", "int64"},    {"uint64", "uint64"}, {"bool", "boolean"}, {"string", "string"},
      {"uint8", "uint8"},    {"int8", "int8"},     {"int16", "int16"},  {"uint16", "uint16"}};
  if (auto it = kPrimitive.find(ros); it != kPrimitive.end()) return it->second;
  const auto slash = ros.find('/');
  if (slash == std::string::npos) return "?" + ros;
  return ros.substr(0, slash) + "::msg::dds_::" + ros.substr(slash + 1) + "_";
}

// Fields of a .msg file as IDL would declare them: "T name" → (T', name), "T[] name" →
// (sequence<T'>, name), "T[N] name" → (T', name[N]).
Fields MsgFields(const std::string& path) {
  Fields out;
  std::istringstream in(Read(path));
  std::string line;
  const std::regex field(R"(^\s*([A-Za-z0-9_/]+)(\[(\d*)\])?\s+([A-Za-z0-9_]+)\s*$)");
  while (std::getline(in, line)) {
    line = line.substr(0, line.find('#'));
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    std::smatch m;
    EXPECT_TRUE(std::regex_match(line, m, field)) << path << ": cannot read '" << line << "'";
    if (m.empty()) continue;
    const std::string type = IdlType(m[1]);
    if (!m[2].matched)
      out.emplace_back(type, m[4]);
    else if (m[3].length() == 0)
      out.emplace_back("sequence<" + type + ">", m[4]);
    else
      out.emplace_back(type, std::string(m[4]) + "[" + std::string(m[3]) + "]");
  }
  return out;
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

TEST(Ros2Msg, BuiltinTypesAreRos2s) {
  const std::string idl = Read(RCAL_DDS_IDL);
  EXPECT_EQ(IdlFields(idl, "Time_"), (Fields{{"int32", "sec"}, {"uint32", "nanosec"}}));
  EXPECT_EQ(IdlFields(idl, "Header_"),
            (Fields{{"builtin_interfaces::msg::dds_::Time_", "stamp"}, {"string", "frame_id"}}));
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
