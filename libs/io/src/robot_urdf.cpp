#include "rcal/io/robot_urdf.hpp"

#include <tinyxml.h>
#include <urdf_parser/urdf_parser.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <functional>
#include <numbers>
#include <stdexcept>

#include "rcal/io/atomic_file.hpp"

namespace rcal::io {
namespace {

/// Checks XML well-formedness first: urdfdom only logs its reasons, tinyxml gives the line.
void ParseXml(TiXmlDocument* doc, const std::string& xml, const std::string& source) {
  doc->Parse(xml.c_str());
  if (doc->Error())
    throw std::runtime_error(source + ": malformed XML: " + doc->ErrorDesc() + " (line " +
                             std::to_string(doc->ErrorRow()) + ")");
}

urdf::ModelInterfaceSharedPtr ParseUrdf(const std::string& xml, const std::string& source) {
  TiXmlDocument doc;
  ParseXml(&doc, xml, source);
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

}  // namespace

RobotSpec ParseUrdfRobotSpec(const std::string& urdf_xml, const std::string& source,
                             const UrdfOptions& options) {
  const urdf::ModelInterfaceSharedPtr urdf = ParseUrdf(urdf_xml, source);
  const std::string base_name =
      options.base_link.empty() ? urdf->getRoot()->name : options.base_link;
  const urdf::LinkConstSharedPtr base = urdf->getLink(base_name);
  if (!base) throw std::runtime_error(source + ": base link '" + base_name + "' not found");

  std::string tip_name = options.tip_link;
  if (tip_name.empty()) {
    // The child link of the deepest moving joint below the base (depth counted in moving
    // joints); fixed frames after it (flange, tool0, cameras) are left to the marker offset and
    // IMU mounting. Two such links (two arms, gripper fingers) are ambiguous.
    int best = 0;
    std::vector<std::string> tied;
    std::function<void(const urdf::Link&, int)> walk = [&](const urdf::Link& l, int moving) {
      for (const auto& c : l.child_links) {
        const bool moves = c->parent_joint && c->parent_joint->type != urdf::Joint::FIXED;
        const int depth = moving + (moves ? 1 : 0);
        if (moves && depth > best) {
          best = depth;
          tied = {c->name};
        } else if (moves && depth == best) {
          tied.push_back(c->name);
        }
        walk(*c, depth);
      }
    };
    walk(*base, 0);
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
      if (!(joint.lower < joint.upper))
        throw std::runtime_error(where + ": lower limit must be below upper limit");
    }
    l.axis = {j->axis.x, j->axis.y, j->axis.z};
    if (!l.axis.allFinite() || l.axis.norm() < 1e-9)
      throw std::runtime_error(where + ": axis must be a nonzero vector");
    l.axis.normalize();
    if (!l.xyz.allFinite() || !l.rpy.allFinite())
      throw std::runtime_error(where + ": origin is not finite");
    l.joint = joint;
    l.identify = options.identify_joints;
    spec.links.push_back(l);
    ++moving;
  }
  if (moving == 0)
    throw std::runtime_error(source + ": no moving joint between '" + base_name + "' and '" +
                             tip_name + "'");
  if (options.add_marker)
    spec.marker = FrameSpec{options.marker_xyz, Eigen::Vector3d::Zero(), options.identify_marker};
  return spec;
}

RobotSpec LoadUrdfRobotSpec(const std::filesystem::path& urdf, const UrdfOptions& options) {
  return ParseUrdfRobotSpec(ReadFile(urdf), urdf.string(), options);
}

kinematics::KinematicModel LoadRobotUrdf(const std::filesystem::path& urdf,
                                         const UrdfOptions& options) {
  return BuildModel(LoadUrdfRobotSpec(urdf, options));
}

std::string CalibratedUrdfText(const std::string& urdf_xml, const std::string& source,
                               const kinematics::KinematicModel& model, const Eigen::VectorXd& x) {
  if (x.size() != model.num_params())
    throw std::runtime_error(source + ": x has " + std::to_string(x.size()) + " values, model '" +
                             model.name() + "' has " + std::to_string(model.num_params()));
  const urdf::ModelInterfaceSharedPtr urdf = ParseUrdf(urdf_xml, source);
  TiXmlDocument doc;
  ParseXml(&doc, urdf_xml, source);
  TiXmlElement* robot = doc.RootElement();

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
  const std::string note =
      " Calibrated by rcal: " + std::to_string(corrected) +
      " joint origins corrected by their identified placement errors. The world-base frame "
      "and the marker offset are not part of a URDF; see the calibrated robot YAML. ";
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
                        const kinematics::KinematicModel& model, const Eigen::VectorXd& x) {
  AtomicWriteFile(out, CalibratedUrdfText(ReadFile(source_urdf), source_urdf.string(), model, x));
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
