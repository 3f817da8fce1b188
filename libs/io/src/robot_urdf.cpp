#include "rcal/io/robot_urdf.hpp"

#include <tinyxml.h>
#include <urdf_parser/urdf_parser.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "rcal/io/atomic_file.hpp"

namespace rcal::io {
namespace {

/// Deepest element nesting accepted. tinyxml parses, copies and frees a document recursively, one
/// stack frame per level, so the file must not choose the depth; a URDF nests 5 or 6 deep.
constexpr int kMaxXmlDepth = 100;

/// Throws when the elements of `xml` nest deeper than kMaxXmlDepth, before tinyxml recurses into
/// them. A scan as tinyxml reads tags: comments, CDATA, declarations and `<!...>` hold no
/// elements; quoted attribute values may hold '>'; `<x/>` opens nothing. Errs only towards a
/// deeper count (a tag tinyxml would refuse still counts), never a shallower one.
void CheckXmlDepth(const std::string& xml, const std::string& source) {
  auto skip_past = [&](size_t from, const char* end) {
    const size_t e = xml.find(end, from);
    return e == std::string::npos ? xml.size() : e + std::strlen(end);
  };
  int depth = 0, line = 1;
  for (size_t i = 0; i < xml.size();) {
    if (xml[i] != '<') {
      line += xml[i] == '\n' ? 1 : 0;
      ++i;
      continue;
    }
    size_t next = 0;
    if (xml.compare(i, 4, "<!--") == 0) {
      next = skip_past(i + 4, "-->");
    } else if (xml.compare(i, 9, "<![CDATA[") == 0) {
      next = skip_past(i + 9, "]]>");
    } else if (xml.compare(i, 2, "<?") == 0 || xml.compare(i, 2, "<!") == 0) {
      next = skip_past(i + 2, ">");
    } else if (xml.compare(i, 2, "</") == 0) {
      next = skip_past(i + 2, ">");
      depth = std::max(0, depth - 1);
    } else {
      // A start tag: to its '>' outside quotes.
      size_t k = i + 1;
      char quote = 0;
      for (; k < xml.size(); ++k) {
        const char c = xml[k];
        if (quote != 0) {
          if (c == quote) quote = 0;
        } else if (c == '"' || c == '\'') {
          quote = c;
        } else if (c == '>') {
          break;
        }
      }
      const bool empty = k < xml.size() && xml[k - 1] == '/';
      if (!empty && ++depth > kMaxXmlDepth)
        throw std::runtime_error(source + ": XML elements nest deeper than " +
                                 std::to_string(kMaxXmlDepth) + " levels (line " +
                                 std::to_string(line) + ")");
      next = k < xml.size() ? k + 1 : xml.size();
    }
    line += static_cast<int>(std::count(xml.begin() + static_cast<std::ptrdiff_t>(i),
                                        xml.begin() + static_cast<std::ptrdiff_t>(next), '\n'));
    i = next;
  }
}

/// The document's <robot> element: the first top-level one, as liburdfdom takes it (not the
/// root element: a document whose first element is something else, e.g. a malformed declaration
/// that tinyxml reads as an element, would otherwise be checked while liburdfdom reads another).
/// A second top-level <robot> is refused: which of two robots a file means is not for rcal to
/// guess.
const TiXmlElement* RobotElement(const TiXmlDocument& doc, const std::string& source) {
  const TiXmlElement* robot = doc.FirstChildElement("robot");
  if (robot == nullptr) throw std::runtime_error(source + ": no top-level <robot> element");
  if (robot->NextSiblingElement("robot") != nullptr)
    throw std::runtime_error(source + ": more than one top-level <robot> element");
  return robot;
}

/// Checks that the <link>s and <joint>s of the <robot> form one tree, naming the joint at fault:
/// every joint names an existing parent and child link, no link is the child of two joints or of
/// its own joint, and no joint's child is an ancestor of its parent (a loop). Iterative, so the
/// file's size, not its shape, bounds the work. Other faults are left to liburdfdom.
void CheckLinkTree(const TiXmlDocument& doc, const std::string& source) {
  const TiXmlElement* robot = RobotElement(doc, source);
  std::set<std::string> links;
  for (const TiXmlElement* l = robot->FirstChildElement("link"); l != nullptr;
       l = l->NextSiblingElement("link")) {
    const char* name = l->Attribute("name");
    if (name == nullptr) throw std::runtime_error(source + ": a <link> has no name");
    if (!links.insert(name).second)
      throw std::runtime_error(source + ": link '" + name + "' is defined twice");
  }
  struct Edge {
    std::string joint, parent;
    int order = 0;  // position of the joint in the file
  };
  std::map<std::string, Edge> parent_of;  // child link → its joint and parent link
  std::set<std::string> joints;
  std::vector<std::pair<std::string, Edge>> second_parents;  // child link → a later joint onto it
  int order = 0;
  for (const TiXmlElement* j = robot->FirstChildElement("joint"); j != nullptr;
       j = j->NextSiblingElement("joint"), ++order) {
    const char* name_attr = j->Attribute("name");
    if (name_attr == nullptr) throw std::runtime_error(source + ": a <joint> has no name");
    const std::string name = name_attr;
    const std::string where = source + ": joint '" + name + "'";
    if (!joints.insert(name).second) throw std::runtime_error(where + ": defined twice");
    auto link_of = [&](const char* role) {
      const TiXmlElement* e = j->FirstChildElement(role);
      const char* link = e != nullptr ? e->Attribute("link") : nullptr;
      if (link == nullptr) throw std::runtime_error(where + ": no <" + role + " link=\"...\"/>");
      if (!links.count(link))
        throw std::runtime_error(where + ": " + role + " link '" + link +
                                 "' is not a <link> of the file");
      return std::string(link);
    };
    const std::string parent = link_of("parent"), child = link_of("child");
    if (parent == child)
      throw std::runtime_error(where + ": link '" + child + "' is both its parent and its child");
    if (!parent_of.emplace(child, Edge{name, parent, order}).second)
      second_parents.push_back({child, Edge{name, parent, order}});
  }
  // Each link has at most one parent, so following parents from any link either reaches a root
  // or runs into a loop. done: links known to reach a root.
  std::set<std::string> done;
  for (const std::string& start : links) {
    std::vector<std::string> path;
    std::set<std::string> on_path;
    std::string l = start;
    for (;;) {
      if (done.count(l)) break;
      if (!on_path.insert(l).second) {
        // The loop is the part of the path from l on; name its last joint in the file.
        const Edge* last = nullptr;
        for (auto p = std::find(path.begin(), path.end(), l); p != path.end(); ++p) {
          const Edge& e = parent_of.at(*p);
          if (last == nullptr || e.order > last->order) last = &e;
        }
        const std::string child = std::find_if(parent_of.begin(), parent_of.end(), [&](auto& kv) {
                                    return &kv.second == last;
                                  })->first;
        throw std::runtime_error(source + ": joint '" + last->joint +
                                 "' closes a loop: its child " + "link '" + child +
                                 "' is an ancestor of its parent link '" + last->parent + "'");
      }
      path.push_back(l);
      const auto p = parent_of.find(l);
      if (p == parent_of.end()) break;
      l = p->second.parent;
    }
    done.insert(path.begin(), path.end());
  }
  // The first parents form a forest now. A later joint onto a link that has one closes a loop
  // when its child is an ancestor of its parent; otherwise the link has two parents.
  for (const auto& [child, e] : second_parents) {
    for (auto p = parent_of.find(e.parent); p != parent_of.end();
         p = parent_of.find(p->second.parent))
      if (p->second.parent == child)
        throw std::runtime_error(source + ": joint '" + e.joint + "' closes a loop: its child " +
                                 "link '" + child + "' is an ancestor of its parent link '" +
                                 e.parent + "'");
    throw std::runtime_error(source + ": joint '" + e.joint + "': link '" + child +
                             "' already has a parent (joint '" + parent_of.at(child).joint +
                             "'); a link has one parent in a URDF tree");
  }
}

/// Checks XML well-formedness first: urdfdom only logs its reasons, tinyxml gives the line.
void ParseXml(TiXmlDocument* doc, const std::string& xml, const std::string& source) {
  CheckXmlDepth(xml, source);
  doc->Parse(xml.c_str());
  if (doc->Error())
    throw std::runtime_error(source + ": malformed XML: " + doc->ErrorDesc() + " (line " +
                             std::to_string(doc->ErrorRow()) + ")");
}

/// Parses a URDF. `origin_rpy`, when given, receives each joint's <origin rpy="..."> as written
/// (liburdfdom keeps only the rotation, which forgets an angle written in degrees).
urdf::ModelInterfaceSharedPtr ParseUrdf(const std::string& xml, const std::string& source,
                                        std::map<std::string, std::string>* origin_rpy = nullptr) {
  TiXmlDocument doc;
  ParseXml(&doc, xml, source);
  // liburdfdom links a loop's links by shared_ptr (leaked) and leaves a link with several parents
  // to its last joint; walking such a tree never ends. Only a proper tree reaches it.
  CheckLinkTree(doc, source);
  if (origin_rpy != nullptr)
    for (const TiXmlElement* j = RobotElement(doc, source)->FirstChildElement("joint");
         j != nullptr; j = j->NextSiblingElement("joint")) {
      const TiXmlElement* o = j->FirstChildElement("origin");
      const char* rpy = o != nullptr ? o->Attribute("rpy") : nullptr;
      if (rpy != nullptr && j->Attribute("name") != nullptr)
        (*origin_rpy)[j->Attribute("name")] = rpy;
    }
  urdf::ModelInterfaceSharedPtr model = urdf::parseURDF(xml);
  if (!model)
    throw std::runtime_error(source +
                             ": not a valid URDF (liburdfdom rejected it; its reason is logged "
                             "above)");
  return model;
}

/// Origin of a joint in its parent link's frame: xyz [m] and roll-pitch-yaw [rad].
void Origin(const urdf::Joint& j, Eigen::Vector3d* xyz, Eigen::Vector3d* rpy) {
  const urdf::Pose& p = j.parent_to_joint_origin_transform;
  *xyz = {p.position.x, p.position.y, p.position.z};
  const Eigen::Quaterniond q(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z);
  *rpy = RobustRpy(q.normalized().toRotationMatrix());
}

/// Largest joint origin offset accepted [m] and largest prismatic |limit| [m]: beyond them a
/// value is a typo or garbage, not an arm (as robot_yaml.hpp's bounds). A revolute limit lies
/// within two turns and an origin's roll, pitch or yaw within a turn (as a robot YAML's): beyond,
/// in degrees most likely. kAngleRounding allows for a rounded π (6.2832 for 2π).
constexpr double kMaxUrdfLength = 100.0;
constexpr double kMaxUrdfLimit = 100.0;
constexpr double kTurn = 2.0 * std::numbers::pi;
constexpr double kAngleRounding = 1e-3;

std::string Num(double v) {
  if (v == 0.0) return "0";
  char buf[64];
  const auto [ptr, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  if (ec != std::errc()) throw std::runtime_error("cannot format a number");
  return std::string(buf, ptr);
}

std::string Triple(const Eigen::Vector3d& v) {
  return Num(v(0)) + " " + Num(v(1)) + " " + Num(v(2));
}

/// ": degrees? URDF angles are radians: 170° is 2.96706" when `value` read as degrees lies within
/// ±bound [rad], else empty.
std::string DegreesHint(double value, double bound) {
  const double rad = value * std::numbers::pi / 180.0;
  if (!(std::abs(rad) <= bound + kAngleRounding)) return "";
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", rad);
  return ": degrees? URDF angles are radians: " + Num(value) + "° is " + buf;
}

/// Refuses an origin rpy (as written, `text`) with an angle beyond a turn, naming degrees.
void CheckOriginRpy(const std::string& text, const std::string& where) {
  std::istringstream in(text);
  for (double v; in >> v;)
    if (std::isfinite(v) && std::abs(v) > kTurn + kAngleRounding)
      throw std::runtime_error(where + ": origin rpy \"" + text + "\": " + Num(v) +
                               " rad is beyond a turn (2π)" + DegreesHint(v, kTurn));
}

}  // namespace

RobotSpec ParseUrdfRobotSpec(const std::string& urdf_xml, const std::string& source,
                             const UrdfOptions& options) {
  std::map<std::string, std::string> origin_rpy;
  const urdf::ModelInterfaceSharedPtr urdf = ParseUrdf(urdf_xml, source, &origin_rpy);
  const std::string base_name =
      options.base_link.empty() ? urdf->getRoot()->name : options.base_link;
  const urdf::LinkConstSharedPtr base = urdf->getLink(base_name);
  if (!base) throw std::runtime_error(source + ": base link '" + base_name + "' not found");

  std::string tip_name = options.tip_link;
  if (tip_name.empty()) {
    // The child link of the deepest moving joint below the base (depth counted in moving
    // joints); fixed frames after it (flange, tool0, cameras) are left to the marker offset and
    // IMU mounting. Two such links (two arms, gripper fingers) are ambiguous.
    // Depth first with an explicit stack (the file must not choose the recursion depth) and a
    // visited set (CheckLinkTree has refused loops; this keeps the walk finite regardless).
    int best = 0;
    std::vector<std::string> tied;
    std::vector<std::pair<const urdf::Link*, int>> stack{{base.get(), 0}};
    std::set<const urdf::Link*> visited{base.get()};
    while (!stack.empty()) {
      const auto [l, moving] = stack.back();
      stack.pop_back();
      // Children pushed in reverse, so they are visited in file order (the order ties are named).
      for (auto c = l->child_links.rbegin(); c != l->child_links.rend(); ++c) {
        if (!visited.insert(c->get()).second)
          throw std::runtime_error(source + ": link '" + (*c)->name + "' is reached twice");
        const bool moves = (*c)->parent_joint && (*c)->parent_joint->type != urdf::Joint::FIXED;
        stack.emplace_back(c->get(), moving + (moves ? 1 : 0));
      }
      if (l == base.get()) continue;
      const bool moves = l->parent_joint && l->parent_joint->type != urdf::Joint::FIXED;
      if (moves && moving > best) {
        best = moving;
        tied = {l->name};
      } else if (moves && moving == best) {
        tied.push_back(l->name);
      }
    }
    if (tied.empty())
      throw std::runtime_error(source + ": no moving joint below base link '" + base_name + "'");
    if (tied.size() != 1) {
      std::string names;
      for (const auto& n : tied) names += (names.empty() ? "" : ", ") + n;
      throw std::runtime_error(source + ": the tip link is ambiguous (links after the deepest " +
                               "moving joints below '" + base_name + "': " + names + "); name one");
    }
    tip_name = tied.front();
  }
  const urdf::LinkConstSharedPtr tip = urdf->getLink(tip_name);
  if (!tip) throw std::runtime_error(source + ": tip link '" + tip_name + "' not found");

  // Walk up from the tip to the base.
  std::vector<urdf::JointConstSharedPtr> chain;
  for (urdf::LinkConstSharedPtr l = tip; l->name != base_name;) {
    // A tree has no path longer than its joints; a longer one would be a loop.
    if (chain.size() > urdf->joints_.size())
      throw std::runtime_error(source + ": the links above tip link '" + tip_name +
                               "' form a loop");
    if (!l->parent_joint)
      throw std::runtime_error(source + ": tip link '" + tip_name + "' is not below base link '" +
                               base_name + "'");
    chain.push_back(l->parent_joint);
    l = urdf->getLink(l->parent_joint->parent_link_name);
    if (!l) throw std::runtime_error(source + ": broken link tree at '" + chain.back()->name + "'");
  }
  std::reverse(chain.begin(), chain.end());

  RobotSpec spec;
  spec.name = urdf->getName();
  spec.convention = Convention::kUrdf;
  if (options.add_base_frame)
    spec.base = FrameSpec{options.base_xyz, options.base_rpy, options.identify_base};
  int moving = 0;
  for (const auto& j : chain) {
    const std::string where = source + ": joint '" + j->name + "'";
    LinkSpec l;
    Origin(*j, &l.xyz, &l.rpy);
    if (!l.xyz.allFinite() || !l.rpy.allFinite())
      throw std::runtime_error(where + ": origin is not finite");
    if (const auto rpy = origin_rpy.find(j->name); rpy != origin_rpy.end())
      CheckOriginRpy(rpy->second, where);
    if (l.xyz.cwiseAbs().maxCoeff() > kMaxUrdfLength)
      throw std::runtime_error(
          where + ": origin xyz beyond " + Num(kMaxUrdfLength) + " m: not an arm's dimension" +
          (l.xyz.cwiseAbs().maxCoeff() * 1e-3 <= kMaxUrdfLength
               ? " (xyz " + Triple(l.xyz) + "): millimetres? URDF lengths are metres"
               : ""));
    if (j->type == urdf::Joint::FIXED) {
      l.name = j->name;
      l.identify = false;
      spec.links.push_back(l);
      continue;
    }
    if (j->mimic) throw std::runtime_error(where + ": mimic joints are not supported");
    kinematics::Joint joint;
    joint.name = j->name;
    switch (j->type) {
      case urdf::Joint::REVOLUTE:
      case urdf::Joint::CONTINUOUS:
        joint.type = kinematics::JointType::kRevolute;
        break;
      case urdf::Joint::PRISMATIC:
        joint.type = kinematics::JointType::kPrismatic;
        break;
      default:
        throw std::runtime_error(where +
                                 ": only revolute, continuous, prismatic and fixed joints "
                                 "are supported");
    }
    if (j->type == urdf::Joint::CONTINUOUS || !j->limits) {
      if (j->type == urdf::Joint::PRISMATIC)
        throw std::runtime_error(where + ": a prismatic joint needs <limit>");
      joint.lower = -std::numbers::pi;
      joint.upper = std::numbers::pi;
    } else {
      joint.lower = j->limits->lower;
      joint.upper = j->limits->upper;
      if (!std::isfinite(joint.lower) || !std::isfinite(joint.upper))
        throw std::runtime_error(where + ": <limit> lower and upper must be finite");
      if (!(joint.lower < joint.upper))
        throw std::runtime_error(where + ": lower limit must be below upper limit");
      const double largest = std::max(std::abs(joint.lower), std::abs(joint.upper));
      const std::string limits =
          " (lower " + Num(joint.lower) + ", upper " + Num(joint.upper) + ")";
      if (j->type == urdf::Joint::PRISMATIC && largest > kMaxUrdfLimit)
        throw std::runtime_error(where + ": <limit> beyond " + Num(kMaxUrdfLimit) + " m" +
                                 (largest * 1e-3 <= kMaxUrdfLimit
                                      ? limits + ": millimetres? URDF prismatic limits are metres"
                                      : ""));
      // Two turns: UR's ±2π, a wrist's ±450° on some arms.
      if (j->type != urdf::Joint::PRISMATIC && largest > 2 * kTurn + kAngleRounding)
        throw std::runtime_error(where + ": <limit>" + limits + " beyond two turns (4π rad)" +
                                 DegreesHint(largest, 2 * kTurn));
    }
    l.axis = {j->axis.x, j->axis.y, j->axis.z};
    if (!l.axis.allFinite() || l.axis.norm() < 1e-9)
      throw std::runtime_error(where + ": axis must be a nonzero vector");
    l.axis.normalize();
    l.joint = joint;
    l.identify = options.identify_joints;
    spec.links.push_back(l);
    ++moving;
  }
  if (moving == 0)
    throw std::runtime_error(source + ": no moving joint between '" + base_name + "' and '" +
                             tip_name + "'");
  CheckArmSize(spec, source);
  if (options.add_marker) spec.markers.push_back({0, options.marker_xyz, options.identify_marker});
  spec.base_link = base_name;
  spec.tip_link = tip_name;
  return spec;
}

RobotSpec LoadUrdfRobotSpec(const std::filesystem::path& urdf, const UrdfOptions& options) {
  return ParseUrdfRobotSpec(ReadFile(urdf), urdf.string(), options);
}

kinematics::KinematicModel LoadRobotUrdf(const std::filesystem::path& urdf,
                                         const UrdfOptions& options) {
  return BuildModel(LoadUrdfRobotSpec(urdf, options));
}

namespace {

Eigen::Isometry3d OriginTransform(const urdf::Joint& j) {
  const urdf::Pose& p = j.parent_to_joint_origin_transform;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  T.linear() = Eigen::Quaterniond(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z)
                   .normalized()
                   .toRotationMatrix();
  return T;
}

Eigen::Isometry3d FromXyzRpy(const Eigen::Vector3d& xyz, const Eigen::Vector3d& rpy) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = xyz;
  T.linear() = (Eigen::AngleAxisd(rpy(2), Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(rpy(1), Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(rpy(0), Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  return T;
}

// A <link name=NAME/> and a fixed <joint> from PARENT to CHILD at origin T, appended to `robot`.
void AppendFixedFrame(TiXmlElement* robot, const std::string& link, const std::string& joint,
                      const std::string& parent, const std::string& child,
                      const Eigen::Isometry3d& T) {
  TiXmlElement l("link");
  l.SetAttribute("name", link);
  robot->InsertEndChild(l);
  TiXmlElement j("joint");
  j.SetAttribute("name", joint);
  j.SetAttribute("type", "fixed");
  TiXmlElement pe("parent"), ce("child"), oe("origin");
  pe.SetAttribute("link", parent);
  ce.SetAttribute("link", child);
  oe.SetAttribute("xyz", Triple(T.translation()));
  oe.SetAttribute("rpy", Triple(RobustRpy(T.linear())));
  j.InsertEndChild(pe);
  j.InsertEndChild(ce);
  j.InsertEndChild(oe);
  robot->InsertEndChild(j);
}

}  // namespace

std::string CalibratedUrdfText(const std::string& urdf_xml, const std::string& source,
                               const RobotSpec& spec, const kinematics::KinematicModel& model,
                               const Eigen::VectorXd& x) {
  if (x.size() != model.num_params())
    throw std::runtime_error(source + ": x has " + std::to_string(x.size()) + " values, model '" +
                             model.name() + "' has " + std::to_string(model.num_params()));
  const urdf::ModelInterfaceSharedPtr urdf = ParseUrdf(urdf_xml, source);
  TiXmlDocument doc;
  ParseXml(&doc, urdf_xml, source);
  RobotElement(doc, source);  // the one <robot>, as checked by ParseUrdf
  TiXmlElement* robot = doc.FirstChildElement("robot");

  const char* suffix[6] = {"_dx", "_dy", "_dz", "_drz", "_dry", "_drx"};
  int corrected = 0;
  for (const kinematics::Joint& mj : model.joints()) {
    Eigen::Matrix<double, 6, 1> e = Eigen::Matrix<double, 6, 1>::Zero();
    bool identified = false;
    for (int k = 0; k < 6; ++k) {
      const int p = model.FindParameter(mj.name + suffix[k]);
      if (p < 0) continue;
      identified = true;
      if (!std::isfinite(x(p)))
        throw std::runtime_error(source + ": parameter '" + mj.name + suffix[k] +
                                 "' is not finite");
      e(k) = x(p);
    }
    if (!identified) continue;
    const urdf::JointConstSharedPtr uj = urdf->getJoint(mj.name);
    if (!uj)
      throw std::runtime_error(source + ": joint '" + mj.name + "' of model '" + model.name() +
                               "' is not in the URDF");
    if (e.isZero(0.0)) continue;
    Eigen::Vector3d xyz, rpy, xyz_new, rpy_new;
    Origin(*uj, &xyz, &rpy);
    ComposeUrdfOrigin(xyz, rpy, e, &xyz_new, &rpy_new);
    TiXmlElement* el = nullptr;
    for (TiXmlElement* j = robot->FirstChildElement("joint"); j != nullptr;
         j = j->NextSiblingElement("joint"))
      if (j->Attribute("name") != nullptr && mj.name == j->Attribute("name")) el = j;
    if (el == nullptr)
      throw std::runtime_error(source + ": joint '" + mj.name + "' not found as <joint>");
    TiXmlElement* origin = el->FirstChildElement("origin");
    if (origin == nullptr) {
      TiXmlElement fresh("origin");
      origin = el->InsertEndChild(fresh)->ToElement();
    }
    origin->SetAttribute("xyz", Triple(xyz_new));
    origin->SetAttribute("rpy", Triple(rpy_new));
    ++corrected;
  }
  // The set-up frames as fixed joints (names in robot_urdf.hpp).
  const RobotSpec cal = CalibratedSpec(spec, model, x);
  std::string frames;
  const auto mention = [&](const std::string& what) {
    frames += (frames.empty() ? "" : ", ") + what;
  };
  if (cal.base) {
    // rcal_world is the parent of the URDF's root; the chain's base link may sit below the root
    // on fixed joints (T_root,base from their origins).
    const urdf::LinkConstSharedPtr root = urdf->getRoot();
    Eigen::Isometry3d T_RB = Eigen::Isometry3d::Identity();
    std::string moving;
    for (urdf::LinkConstSharedPtr l = urdf->getLink(spec.base_link); l && l != root;
         l = l->getParent()) {
      const urdf::JointConstSharedPtr pj = l->parent_joint;
      if (!pj) break;
      if (pj->type != urdf::Joint::FIXED) moving = pj->name;
      T_RB = OriginTransform(*pj) * T_RB;
    }
    if (!urdf->getLink(spec.base_link))
      throw std::runtime_error(source + ": base link '" + spec.base_link + "' is not in the URDF");
    if (moving.empty()) {
      const Eigen::Isometry3d T_WB = FromXyzRpy(cal.base->xyz, cal.base->rpy);
      AppendFixedFrame(robot, "rcal_world", "rcal_world_joint", "rcal_world", root->name,
                       T_WB * T_RB.inverse());
      mention("rcal_world (the position sensor's frame) -> " + root->name);
      if (cal.earth) {
        AppendFixedFrame(robot, "rcal_earth", "rcal_earth_joint", "rcal_earth", "rcal_world",
                         FromXyzRpy(Eigen::Vector3d::Zero(), cal.earth->rpy));
        mention("rcal_earth (the IMU's earth frame) -> rcal_world");
      }
    } else {
      mention("no rcal_world: joint '" + moving + "' between the root and base link '" +
              spec.base_link + "' moves (world <- base is in the calibrated robot YAML)");
    }
  }
  for (const MarkerSpec& m : cal.markers) {
    const std::string name = UrdfMarkerLink(m.id);
    AppendFixedFrame(robot, name, name + "_joint", spec.tip_link, name,
                     FromXyzRpy(m.xyz, Eigen::Vector3d::Zero()));
    mention(spec.tip_link + " -> " + name);
  }
  if (cal.imu) {
    AppendFixedFrame(robot, "rcal_imu", "rcal_imu_joint", spec.tip_link, "rcal_imu",
                     FromXyzRpy(Eigen::Vector3d::Zero(), cal.imu->rpy));
    mention(spec.tip_link + " -> rcal_imu (orientation only)");
  }
  const std::string note = " Calibrated by rcal: chain " + spec.base_link + " -> " + spec.tip_link +
                           "; " + std::to_string(corrected) +
                           " joint origins corrected by their identified placement errors; "
                           "set-up frames as fixed joints: " +
                           (frames.empty() ? std::string("none") : frames) + ". ";
  TiXmlComment comment(note.c_str());
  if (robot->FirstChild() != nullptr) {
    robot->InsertBeforeChild(robot->FirstChild(), comment);
  } else {
    robot->InsertEndChild(comment);
  }

  TiXmlPrinter printer;
  printer.SetIndent("  ");
  doc.Accept(&printer);
  return printer.Str();
}

void SaveCalibratedUrdf(const std::filesystem::path& source_urdf, const std::filesystem::path& out,
                        const RobotSpec& spec, const kinematics::KinematicModel& model,
                        const Eigen::VectorXd& x) {
  AtomicWriteFile(out,
                  CalibratedUrdfText(ReadFile(source_urdf), source_urdf.string(), spec, model, x));
}

std::string UrdfMarkerLink(int marker_id) {
  return marker_id == 0 ? "rcal_marker" : "rcal_marker_" + std::to_string(marker_id);
}

namespace {

/// The value of an ET at parameter errors x and no joint motion [m | rad].
double EtValue(const kinematics::ElementaryTransform& et, const Eigen::VectorXd& x) {
  return et.param >= 0 ? et.nominal + x(et.param) : et.nominal;
}

/// The product of ETs [first, last) at x.
Eigen::Isometry3d EtProduct(const std::vector<kinematics::ElementaryTransform>& ets, size_t first,
                            size_t last, const Eigen::VectorXd& x) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (size_t i = first; i < last; ++i) T = T * kinematics::EtTransform(ets[i], EtValue(ets[i], x));
  return T;
}

/// A name as an XML attribute value (a robot file's names are free text).
std::string XmlAttr(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

/// `<joint>` text of a fixed or moving joint with origin T (xyz, rpy at full precision).
std::string JointXml(const std::string& name, const std::string& type, const std::string& parent,
                     const std::string& child, const Eigen::Isometry3d& T,
                     const std::string& extra = {}) {
  return "  <joint name=\"" + XmlAttr(name) + "\" type=\"" + type + "\">\n    <parent link=\"" +
         XmlAttr(parent) + "\"/>\n    <child link=\"" + XmlAttr(child) +
         "\"/>\n    <origin xyz=\"" + Triple(T.translation()) + "\" rpy=\"" +
         Triple(RobustRpy(T.linear())) + "\"/>\n" + extra + "  </joint>\n";
}

/// XML comments may not hold "--".
std::string CommentSafe(std::string s) {
  for (size_t i = s.find("--"); i != std::string::npos; i = s.find("--", i)) s.replace(i, 2, "- ");
  return s;
}

}  // namespace

std::string SpecUrdfText(const RobotSpec& spec, const kinematics::KinematicModel& model,
                         const Eigen::VectorXd& x) {
  if (x.size() != model.num_params())
    throw std::runtime_error("robot '" + model.name() + "': x has " + std::to_string(x.size()) +
                             " values, the model has " + std::to_string(model.num_params()));
  for (int i = 0; i < x.size(); ++i)
    if (!std::isfinite(x(i)))
      throw std::runtime_error("robot '" + model.name() + "': parameter '" +
                               model.parameters()[i].name + "' is not finite");
  using kinematics::Segment;
  const auto& chain = model.ets(Segment::kChain);
  // The chain is [base frame (6 ETs)] links and tool [marker (3 ETs)] (kinematics/model.hpp).
  const size_t first = spec.base ? 6 : 0;
  const size_t last = chain.size() - (model.markers().empty() ? 0 : 3);
  if (first > last)
    throw std::runtime_error("robot '" + model.name() + "': the model is not BuildModel(spec)");
  std::string links, joints;
  const auto link = [&](const std::string& name) {
    links += "  <link name=\"" + XmlAttr(name) + "\"/>\n";
  };
  link(spec.base_link);
  std::string world = spec.base_link;
  if (spec.base) {
    link("rcal_world");
    joints += JointXml("rcal_world_joint", "fixed", "rcal_world", spec.base_link,
                       EtProduct(chain, 0, first, x));
    world = "rcal_world";
  }
  const auto& earth = model.ets(Segment::kEarth);
  if (!earth.empty()) {
    link("rcal_earth");
    joints += JointXml("rcal_earth_joint", "fixed", "rcal_earth", world,
                       EtProduct(earth, 0, earth.size(), x));
  }
  // A joint's ET value is (nominal + x) + q: about one axis the constant part commutes with the
  // motion, so a joint is origin F · motion(q) and its constant part starts the next origin.
  Eigen::Isometry3d F = Eigen::Isometry3d::Identity();
  std::string parent = spec.base_link;
  int moving = 0;
  for (size_t i = first; i < last; ++i) {
    const kinematics::ElementaryTransform& et = chain[i];
    if (et.joint < 0) {
      F = F * kinematics::EtTransform(et, EtValue(et, x));
      continue;
    }
    const kinematics::Joint& j = model.joints().at(et.joint);
    // "link<i>" after joint i, unless the chain's own ends are called so (a 7-joint arm whose
    // tip link is "link7").
    std::string child = "link" + std::to_string(++moving);
    if (child == spec.base_link || child == spec.tip_link) child = "rcal_" + child;
    const bool rotation = et.kind == kinematics::ElementaryTransform::Kind::kRotation;
    link(child);
    joints +=
        JointXml(j.name, rotation ? "revolute" : "prismatic", parent, child, F,
                 "    <axis xyz=\"" + Triple(et.axis) + "\"/>\n    <limit lower=\"" + Num(j.lower) +
                     "\" upper=\"" + Num(j.upper) + "\" effort=\"0\" velocity=\"0\"/>\n");
    F = kinematics::EtTransform(et, EtValue(et, x));
    parent = child;
  }
  link(spec.tip_link);
  joints += JointXml(spec.tip_link + "_joint", "fixed", parent, spec.tip_link, F);
  for (const kinematics::Marker& m : model.markers()) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    for (int a = 0; a < 3; ++a)
      T.translation()(a) = m.param[a] >= 0 ? m.nominal(a) + x(m.param[a]) : m.nominal(a);
    link(UrdfMarkerLink(m.id));
    joints +=
        JointXml(UrdfMarkerLink(m.id) + "_joint", "fixed", spec.tip_link, UrdfMarkerLink(m.id), T);
  }
  const auto& imu = model.ets(Segment::kImu);
  if (!imu.empty()) {
    link("rcal_imu");
    joints += JointXml("rcal_imu_joint", "fixed", spec.tip_link, "rcal_imu",
                       EtProduct(imu, 0, imu.size(), x));
  }
  return "<?xml version=\"1.0\"?>\n<robot name=\"" + XmlAttr(model.name()) + "\">\n" + "  <!-- " +
         CommentSafe("Written by rcal from the robot description (" +
                     std::string(spec.convention == Convention::kDh           ? "D-H"
                                 : spec.convention == Convention::kModifiedDh ? "modified D-H"
                                                                              : "URDF-style") +
                     " links): chain " + spec.base_link + " -> " + spec.tip_link +
                     "; set-up frames rcal_world (the position sensor's frame) <- " +
                     spec.base_link + ", " + spec.tip_link + " -> rcal_marker, " + spec.tip_link +
                     " -> rcal_imu, rcal_earth (the IMU's earth frame) <- world, where the "
                     "model has them. ") +
         "-->\n" + links + joints + "</robot>\n";
}

std::string RobotDescriptionUrdf(const RobotSpec& spec, const kinematics::KinematicModel& model,
                                 const Eigen::VectorXd& x, const std::string& urdf_xml,
                                 const std::string& source,
                                 const std::vector<std::string>& header) {
  std::string text = urdf_xml.empty() ? SpecUrdfText(spec, model, x)
                                      : CalibratedUrdfText(urdf_xml, source, spec, model, x);
  std::string comments;
  for (const std::string& h : header) comments += "<!-- " + CommentSafe(h) + " -->\n";
  // After the XML declaration, which must come first.
  size_t at = 0;
  if (text.compare(0, 5, "<?xml") == 0) {
    const size_t end = text.find("?>");
    at = end == std::string::npos ? 0 : end + 2;
    if (at < text.size() && text[at] == '\n') ++at;
  }
  text.insert(at, comments);
  return text;
}

UrdfChain::UrdfChain(const std::string& urdf_xml, const std::string& source,
                     const std::string& root_link, const std::string& tip_link) {
  const urdf::ModelInterfaceSharedPtr urdf = ParseUrdf(urdf_xml, source);
  if (!urdf->getLink(root_link))
    throw std::runtime_error(source + ": link '" + root_link + "' not found");
  urdf::LinkConstSharedPtr l = urdf->getLink(tip_link);
  if (!l) throw std::runtime_error(source + ": link '" + tip_link + "' not found");
  std::vector<urdf::JointConstSharedPtr> path;
  for (; l->name != root_link; l = urdf->getLink(l->parent_joint->parent_link_name)) {
    if (!l->parent_joint || path.size() > urdf->joints_.size())
      throw std::runtime_error(source + ": link '" + tip_link + "' is not below link '" +
                               root_link + "'");
    path.push_back(l->parent_joint);
    if (!urdf->getLink(l->parent_joint->parent_link_name))
      throw std::runtime_error(source + ": joint '" + l->parent_joint->name +
                               "': parent link not found");
  }
  std::reverse(path.begin(), path.end());
  for (const urdf::JointConstSharedPtr& j : path) {
    Step s;
    s.origin = OriginTransform(*j);
    s.axis = Eigen::Vector3d(j->axis.x, j->axis.y, j->axis.z);
    if (j->mimic) throw std::runtime_error(source + ": joint '" + j->name + "' is a mimic joint");
    switch (j->type) {
      case urdf::Joint::FIXED:
        break;
      case urdf::Joint::REVOLUTE:
      case urdf::Joint::CONTINUOUS:
      case urdf::Joint::PRISMATIC:
        if (!s.axis.allFinite() || s.axis.norm() < 1e-9)
          throw std::runtime_error(source + ": joint '" + j->name + "': axis is not a direction");
        s.axis.normalize();
        s.prismatic = j->type == urdf::Joint::PRISMATIC;
        s.joint = static_cast<int>(joint_names_.size());
        joint_names_.push_back(j->name);
        break;
      default:
        throw std::runtime_error(source + ": joint '" + j->name +
                                 "': floating and planar joints have no single joint value");
    }
    steps_.push_back(s);
  }
}

Eigen::Isometry3d UrdfChain::Pose(const Eigen::VectorXd& q) const {
  if (q.size() != static_cast<Eigen::Index>(joint_names_.size()))
    throw std::invalid_argument("UrdfChain: q has " + std::to_string(q.size()) + " values, the " +
                                "chain has " + std::to_string(joint_names_.size()) + " joints");
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (const Step& s : steps_) {
    T = T * s.origin;
    if (s.joint < 0) continue;
    if (s.prismatic) {
      T.translate(q(s.joint) * s.axis);
    } else {
      T.rotate(Eigen::AngleAxisd(q(s.joint), s.axis));
    }
  }
  return T;
}

LoadedRobot LoadRobot(const std::filesystem::path& path, const UrdfOptions& urdf_options) {
  LoadedRobot r;
  r.source = path;
  std::string ext = path.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".urdf") {
    r.from_urdf = true;
    r.spec = LoadUrdfRobotSpec(path, urdf_options);
  } else if (ext == ".yaml" || ext == ".yml") {
    r.spec = LoadRobotSpec(path);
  } else {
    throw std::runtime_error(path.string() + ": unknown robot file type (expected .yaml or .urdf)");
  }
  r.model = BuildModel(r.spec);
  return r;
}

}  // namespace rcal::io
