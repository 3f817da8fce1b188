#include "process_table.hpp"

#include <yaml-cpp/yaml.h>

#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>

namespace rcal::services {
namespace {

[[noreturn]] void Fail(const std::string& source, const std::string& key, const std::string& what,
                       const YAML::Node& node) {
  std::string line;
  if (node.Mark().line >= 0) line = " (line " + std::to_string(node.Mark().line + 1) + ")";
  throw std::runtime_error(source + ": " + key + ": " + what + line);
}

void OnlyKeys(const YAML::Node& map, const std::set<std::string>& allowed,
              const std::string& source, const std::string& path) {
  if (!map.IsMap()) Fail(source, path.empty() ? "<root>" : path, "not a mapping", map);
  for (const auto& kv : map) {
    const std::string key = kv.first.as<std::string>();
    if (!allowed.count(key))
      Fail(source, path + (path.empty() ? "" : ".") + key, "unknown key", kv.first);
  }
}

template <typename T>
T Get(const YAML::Node& node, const std::string& source, const std::string& key) {
  try {
    return node.as<T>();
  } catch (const YAML::Exception&) {
    Fail(source, key, "wrong type", node);
  }
}

}  // namespace

ProcessTable ParseProcessTable(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(source + ": not YAML: " + e.what());
  }
  OnlyKeys(root, {"schema", "lcm_url", "log_dir", "policy", "processes"}, source, "");
  if (!root["schema"] || Get<std::string>(root["schema"], source, "schema") != "rcal.processes/1")
    Fail(source, "schema", "expected rcal.processes/1", root["schema"] ? root["schema"] : root);
  ProcessTable t;
  if (root["lcm_url"]) t.lcm_url = Get<std::string>(root["lcm_url"], source, "lcm_url");
  if (root["log_dir"]) t.log_dir = Get<std::string>(root["log_dir"], source, "log_dir");
  if (const auto p = root["policy"]) {
    OnlyKeys(p,
             {"backoff_initial", "backoff_factor", "backoff_max", "healthy_run", "fast_crash",
              "max_fast_crashes", "crash_window", "stop_timeout", "startup_grace"},
             source, "policy");
    auto num = [&](const char* key, double& v) {
      if (p[key]) v = Get<double>(p[key], source, std::string("policy.") + key);
    };
    num("backoff_initial", t.policy.backoff_initial);
    num("backoff_factor", t.policy.backoff_factor);
    num("backoff_max", t.policy.backoff_max);
    num("healthy_run", t.policy.healthy_run);
    num("fast_crash", t.policy.fast_crash);
    num("crash_window", t.policy.crash_window);
    num("stop_timeout", t.policy.stop_timeout);
    num("startup_grace", t.policy.startup_grace);
    if (p["max_fast_crashes"])
      t.policy.max_fast_crashes =
          Get<int>(p["max_fast_crashes"], source, "policy.max_fast_crashes");
  }
  const auto procs = root["processes"];
  if (!procs || !procs.IsSequence() || procs.size() == 0)
    Fail(source, "processes", "required, a non-empty list", procs ? procs : root);
  std::set<std::string> names;
  for (size_t i = 0; i < procs.size(); ++i) {
    const std::string path = "processes[" + std::to_string(i) + "]";
    const auto n = procs[i];
    OnlyKeys(n, {"name", "command", "heartbeat_timeout"}, source, path);
    supervisor::ProcessSpec spec;
    if (!n["name"]) Fail(source, path + ".name", "required", n);
    spec.name = Get<std::string>(n["name"], source, path + ".name");
    if (spec.name.empty() || !names.insert(spec.name).second)
      Fail(source, path + ".name", "empty or duplicate", n["name"]);
    if (!n["command"] || !n["command"].IsSequence() || n["command"].size() == 0)
      Fail(source, path + ".command", "required, a non-empty list",
           n["command"] ? n["command"] : n);
    for (size_t k = 0; k < n["command"].size(); ++k)
      spec.argv.push_back(
          Get<std::string>(n["command"][k], source, path + ".command[" + std::to_string(k) + "]"));
    if (n["heartbeat_timeout"])
      spec.heartbeat_timeout =
          Get<double>(n["heartbeat_timeout"], source, path + ".heartbeat_timeout");
    t.processes.push_back(std::move(spec));
  }
  return t;
}

ProcessTable LoadProcessTable(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path.string() + ": cannot read");
  std::stringstream ss;
  ss << in.rdbuf();
  return ParseProcessTable(ss.str(), path.string());
}

}  // namespace rcal::services
