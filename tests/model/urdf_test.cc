// The URDF loader (MODELS.md "Articulated bodies from URDF"): the shipped
// models, exact welding of fixed joints, the root and floating base, the
// ignored-features note, and every rejection, inline and from the bad-input
// corpus (tests/data/bad/urdf_*.urdf with their fragments in expected.txt).

#include "stiffsim/model/urdf.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/model/rigid_tree.h"

namespace stiffsim {
namespace {

namespace fs = std::filesystem;

const fs::path kSource(STIFFSIM_SOURCE_DIR);
const fs::path kModels = kSource / "models";
const fs::path kBad = kSource / "tests" / "data" / "bad";

std::string read(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

RigidTree parse(const std::string& xml, std::vector<std::string>* notes = nullptr,
                bool floating_base = false) {
  UrdfOptions options;
  options.floating_base = floating_base;
  return parse_urdf(xml, "test.urdf", options, notes);
}

// The InputError message of parsing `xml`, or "" if it loads.
std::string error_of(const std::string& xml, bool floating_base = false) {
  try {
    parse(xml, nullptr, floating_base);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

// A link with a diagonal unit-ish inertia, for trees whose masses do not
// matter.
std::string link(const std::string& name, double mass = 1.0) {
  std::ostringstream out;
  out << "<link name='" << name << "'><inertial><mass value='" << mass
      << "'/><inertia ixx='1' iyy='2' izz='3' ixy='0' ixz='0' iyz='0'/></inertial></link>";
  return out.str();
}

std::string joint(const std::string& name, const std::string& type, const std::string& parent,
                  const std::string& child, const std::string& extra = "") {
  return "<joint name='" + name + "' type='" + type + "'><parent link='" + parent +
         "'/><child link='" + child + "'/>" + extra + "</joint>";
}

std::string robot(const std::string& body) { return "<robot name='r'>" + body + "</robot>"; }

// Independent of urdfdom's quaternions: URDF rpy is fixed-axis roll about
// x, then pitch about y, then yaw about z.
Eigen::Matrix3d rpy(double r, double p, double y) {
  return (Eigen::AngleAxisd(y, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(p, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(r, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Eigen::Matrix3d tensor(double ixx, double iyy, double izz, double ixy, double ixz, double iyz) {
  Eigen::Matrix3d t;
  t << ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz;
  return t;
}

void expect_near(const Eigen::MatrixXd& actual, const Eigen::MatrixXd& expected, double tol,
                 const std::string& what) {
  ASSERT_EQ(actual.rows(), expected.rows()) << what;
  ASSERT_EQ(actual.cols(), expected.cols()) << what;
  EXPECT_LE((actual - expected).cwiseAbs().maxCoeff(), tol)
      << what << "\nactual:\n" << actual << "\nexpected:\n" << expected;
}

// --- rigid_tree.h -----------------------------------------------------------

TEST(RigidTree, JointDimensions) {
  EXPECT_EQ(joint_nq(JointType::kRevolute), 1);
  EXPECT_EQ(joint_nv(JointType::kRevolute), 1);
  EXPECT_EQ(joint_nq(JointType::kPrismatic), 1);
  EXPECT_EQ(joint_nv(JointType::kPrismatic), 1);
  EXPECT_EQ(joint_nq(JointType::kFloating), 7);
  EXPECT_EQ(joint_nv(JointType::kFloating), 6);
  EXPECT_EQ(joint_nq(JointType::kPlanar), 3);
  EXPECT_EQ(joint_nv(JointType::kPlanar), 3);
  EXPECT_STREQ(joint_type_name(JointType::kRevolute), "revolute");
  EXPECT_STREQ(joint_type_name(JointType::kPrismatic), "prismatic");
  EXPECT_STREQ(joint_type_name(JointType::kFloating), "floating");
  EXPECT_STREQ(joint_type_name(JointType::kPlanar), "planar");
}

TEST(RigidTree, CombineTwoPointMassesIsADumbbell) {
  RigidInertia a, b;
  a.mass = 1.0;
  a.com = Eigen::Vector3d(-1, 0, 0);
  b.mass = 3.0;
  b.com = Eigen::Vector3d(1, 0, 0);
  const RigidInertia sum = combine(a, b);
  EXPECT_DOUBLE_EQ(sum.mass, 4.0);
  expect_near(sum.com, Eigen::Vector3d(0.5, 0, 0), 1e-15, "com");
  // About the COM: 1 * 1.5^2 + 3 * 0.5^2 = 3 about y and z, 0 about x.
  expect_near(sum.inertia, Eigen::Vector3d(0, 3, 3).asDiagonal().toDenseMatrix(), 1e-14,
              "inertia");
}

TEST(RigidTree, TransformRotatesTheTensorAndMovesTheCom) {
  RigidInertia in;
  in.mass = 2.0;
  in.com = Eigen::Vector3d(1, 0, 0);
  in.inertia = Eigen::Vector3d(1, 2, 3).asDiagonal();
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(0, 0, 5);
  const RigidInertia out = transform(in, pose);
  EXPECT_EQ(out.mass, 2.0);
  expect_near(out.com, Eigen::Vector3d(0, 1, 5), 1e-15, "com");
  expect_near(out.inertia, Eigen::Vector3d(2, 1, 3).asDiagonal().toDenseMatrix(), 1e-15,
              "inertia");
}

// --- shipped models ---------------------------------------------------------

TEST(UrdfModels, Chain2MatchesModelsMd) {
  std::vector<std::string> notes;
  const RigidTree tree = load_urdf((kModels / "chain_2.urdf").string(), {}, &notes);
  EXPECT_EQ(tree.name, "chain_2");
  EXPECT_EQ(tree.file, (kModels / "chain_2.urdf").string());
  EXPECT_TRUE(notes.empty()) << notes.front();
  ASSERT_EQ(tree.bodies.size(), 2u);
  const double m = 0.1, l = 0.1;
  for (int i = 0; i < 2; ++i) {
    const TreeBody& b = tree.bodies[i];
    SCOPED_TRACE(b.link);
    EXPECT_EQ(b.link, "link_" + std::to_string(i + 1));
    EXPECT_EQ(b.joint, "joint_" + std::to_string(i + 1));
    EXPECT_EQ(b.parent, i - 1);
    EXPECT_EQ(b.type, JointType::kRevolute);  // URDF continuous
    expect_near(b.axis, Eigen::Vector3d::UnitY(), 0.0, "axis");
    expect_near(b.placement.linear(), Eigen::Matrix3d::Identity(), 0.0, "placement rotation");
    expect_near(b.placement.translation(), Eigen::Vector3d(0, 0, i == 0 ? 0.0 : -l), 0.0,
                "placement translation");
    EXPECT_DOUBLE_EQ(b.inertia.mass, m);
    expect_near(b.inertia.com, Eigen::Vector3d(0, 0, -l / 2), 1e-17, "com");
    expect_near(b.inertia.inertia,
                Eigen::Vector3d(m * l * l / 12, m * l * l / 12, 1e-6).asDiagonal().toDenseMatrix(),
                1e-18, "inertia");
    EXPECT_EQ(b.damping, 0.0);
  }
}

TEST(UrdfModels, LongChainsAreSerial) {
  for (int n : {10, 100, 1000}) {
    const std::string file = "chain_" + std::to_string(n) + ".urdf";
    const RigidTree tree = load_urdf((kModels / file).string(), {}, nullptr);
    ASSERT_EQ(tree.bodies.size(), static_cast<size_t>(n)) << file;
    for (int i = 0; i < n; ++i) {
      ASSERT_EQ(tree.bodies[i].parent, i - 1) << file;
      ASSERT_EQ(tree.bodies[i].link, "link_" + std::to_string(i + 1)) << file;
    }
  }
}

TEST(UrdfModels, TreeLoadsWithItsJunkIgnoredOnce) {
  std::vector<std::string> notes;
  UrdfOptions options;
  options.component_name = "robot";
  const std::string path = (kModels / "tree.urdf").string();
  const RigidTree tree = load_urdf(path, options, &notes);
  EXPECT_EQ(tree.name, "robot");
  ASSERT_EQ(notes.size(), 1u);
  const std::string& note = notes[0];
  EXPECT_EQ(note.rfind(path + ": ignored (no effect on the dynamics here): ", 0), 0u) << note;
  for (const char* part : {"joint limits (6 joints)", "mimic (1 joint)", "friction (2 joints)",
                           "visual/collision geometry (7 links)", "materials (2)",
                           "transmissions (1)", "gazebo blocks (1)"}) {
    EXPECT_NE(note.find(part), std::string::npos) << part << " not in: " << note;
  }
  EXPECT_EQ(note.find('\n'), std::string::npos);

  // File order, depth first; fixed joints (battery, IMU frame, gripper) are
  // welded away.
  const std::vector<std::string> links = {"torso",          "head",         "left_upper_arm",
                                          "left_forearm",   "left_hand",    "right_upper_arm",
                                          "right_forearm",  "right_hand"};
  const std::vector<int> parents = {-1, 0, 0, 2, 3, 0, 5, 6};
  ASSERT_EQ(tree.bodies.size(), links.size());
  int prismatic = 0;
  for (size_t i = 0; i < links.size(); ++i) {
    EXPECT_EQ(tree.bodies[i].link, links[i]);
    EXPECT_EQ(tree.bodies[i].parent, parents[i]) << links[i];
    EXPECT_NEAR(tree.bodies[i].axis.norm(), 1.0, 1e-15) << links[i];
    prismatic += tree.bodies[i].type == JointType::kPrismatic;
  }
  EXPECT_EQ(prismatic, 1);
  EXPECT_DOUBLE_EQ(tree.bodies[0].inertia.mass, 13.0);  // torso + battery
  EXPECT_DOUBLE_EQ(tree.bodies[7].inertia.mass, 0.8);   // hand + gripper
  EXPECT_EQ(tree.bodies[0].damping, 0.5);
  EXPECT_EQ(tree.bodies[6].damping, 5.0);
  EXPECT_EQ(tree.bodies[3].damping, 0.0);
  expect_near(tree.bodies[4].axis, Eigen::Vector3d(0, 0.6, 0.8), 1e-15, "skew wrist axis");
}

TEST(UrdfModels, FreeBodyWithFloatingBase) {
  UrdfOptions options;
  options.floating_base = true;
  const RigidTree tree = load_urdf((kModels / "free_body.urdf").string(), options, nullptr);
  ASSERT_EQ(tree.bodies.size(), 1u);
  const TreeBody& box = tree.bodies[0];
  EXPECT_EQ(box.link, "box");
  EXPECT_EQ(box.joint, "floating_base");
  EXPECT_EQ(box.type, JointType::kFloating);
  EXPECT_EQ(box.parent, -1);
  EXPECT_TRUE(box.placement.isApprox(Eigen::Isometry3d::Identity(), 0.0));
  const double a = 0.1, b = 0.2, c = 0.4;
  expect_near(box.inertia.inertia,
              Eigen::Vector3d(b * b + c * c, a * a + c * c, a * a + b * b).asDiagonal().toDenseMatrix() /
                  12.0,
              1e-15, "box inertia");
  EXPECT_GT(box.inertia.inertia(0, 0), box.inertia.inertia(1, 1));
  EXPECT_GT(box.inertia.inertia(1, 1), box.inertia.inertia(2, 2));
}

// --- welding and structure --------------------------------------------------

// A parent and a fixed child, both with rpy-rotated inertial frames and
// products of inertia, under a fixed joint that is itself rotated: the welded
// body must carry exactly the rigid union's mass, COM and inertia about it.
TEST(Urdf, WeldingAFixedChildIsTheRigidUnion) {
  const std::string xml = robot(
      "<link name='base'/>" + joint("hinge", "continuous", "base", "p", "<axis xyz='0 0 1'/>") +
      "<link name='p'><inertial><origin xyz='0.1 -0.2 0.3' rpy='0.3 -0.2 0.5'/>"
      "<mass value='2'/><inertia ixx='0.5' iyy='0.4' izz='0.3' ixy='0.02' ixz='-0.01' "
      "iyz='0.03'/></inertial></link>" +
      joint("weld", "fixed", "p", "c", "<origin xyz='0.4 0.1 -0.2' rpy='-0.4 0.7 1.1'/>") +
      "<link name='c'><inertial><origin xyz='-0.05 0.02 0.1' rpy='1.0 0.2 -0.3'/>"
      "<mass value='0.7'/><inertia ixx='0.06' iyy='0.05' izz='0.02' ixy='-0.004' ixz='0.002' "
      "iyz='0.001'/></inertial></link>");
  const RigidTree tree = parse(xml);
  ASSERT_EQ(tree.bodies.size(), 1u);
  const RigidInertia& welded = tree.bodies[0].inertia;

  // By hand, in p's frame.
  const double mp = 2.0, mc = 0.7;
  const Eigen::Vector3d cp(0.1, -0.2, 0.3);
  const Eigen::Matrix3d rp = rpy(0.3, -0.2, 0.5);
  const Eigen::Matrix3d ip = rp * tensor(0.5, 0.4, 0.3, 0.02, -0.01, 0.03) * rp.transpose();
  const Eigen::Matrix3d rw = rpy(-0.4, 0.7, 1.1);  // c's frame in p's
  const Eigen::Vector3d tw(0.4, 0.1, -0.2);
  const Eigen::Vector3d cc = tw + rw * Eigen::Vector3d(-0.05, 0.02, 0.1);
  const Eigen::Matrix3d rc = rw * rpy(1.0, 0.2, -0.3);
  const Eigen::Matrix3d ic = rc * tensor(0.06, 0.05, 0.02, -0.004, 0.002, 0.001) * rc.transpose();
  const double m = mp + mc;
  const Eigen::Vector3d com = (mp * cp + mc * cc) / m;
  auto steiner = [](double mass, const Eigen::Vector3d& d) {
    return Eigen::Matrix3d(mass * (d.dot(d) * Eigen::Matrix3d::Identity() - d * d.transpose()));
  };
  const Eigen::Matrix3d inertia = ip + steiner(mp, cp - com) + ic + steiner(mc, cc - com);

  EXPECT_DOUBLE_EQ(welded.mass, m);
  expect_near(welded.com, com, 1e-15, "com");
  expect_near(welded.inertia, inertia, 1e-14, "inertia about the COM");
  EXPECT_EQ(welded.inertia, welded.inertia.transpose());
}

// A moving grandchild behind a chain of fixed joints hangs from the body
// they were welded into, at the composed placement.
TEST(Urdf, FixedChainsComposePlacements) {
  const std::string xml = robot(
      "<link name='base'/>" + joint("j1", "continuous", "base", "a") + link("a") +
      joint("f1", "fixed", "a", "b", "<origin xyz='1 0 0' rpy='0 0 1.5707963267948966'/>") +
      link("b") + joint("f2", "fixed", "b", "c", "<origin xyz='0 2 0'/>") + "<link name='c'/>" +
      joint("j2", "prismatic", "c", "d",
            "<origin xyz='0 0 3'/><axis xyz='0 0 2'/><limit effort='1' velocity='1'/>") +
      link("d"));
  const RigidTree tree = parse(xml);
  ASSERT_EQ(tree.bodies.size(), 2u);
  EXPECT_EQ(tree.bodies[1].link, "d");
  EXPECT_EQ(tree.bodies[1].parent, 0);
  EXPECT_EQ(tree.bodies[1].type, JointType::kPrismatic);
  expect_near(tree.bodies[1].axis, Eigen::Vector3d::UnitZ(), 0.0, "normalized axis");
  // c sits at (1, 0, 0) + Rz(90°) (0, 2, 0) = (-1, 0, 0) in a, d 3 above it.
  expect_near(tree.bodies[1].placement.translation(), Eigen::Vector3d(-1, 0, 3), 1e-15,
              "composed translation");
  expect_near(tree.bodies[1].placement.linear(), rpy(0, 0, M_PI / 2), 1e-15, "composed rotation");
  EXPECT_DOUBLE_EQ(tree.bodies[0].inertia.mass, 2.0);  // a + b; c is massless
}

TEST(Urdf, AMasslessFrameOnAFixedJointChangesNothing) {
  const std::string arm = "<link name='base'/>" + joint("j", "continuous", "base", "arm") +
                          "<link name='arm'><inertial><origin xyz='0.1 0.2 0.3' rpy='0.4 0.5 "
                          "0.6'/><mass value='1.3'/><inertia ixx='0.5' iyy='0.4' izz='0.3' "
                          "ixy='0.02' ixz='-0.01' iyz='0.03'/></inertial></link>";
  const RigidTree plain = parse(robot(arm));
  const RigidTree framed = parse(robot(
      arm + joint("mount", "fixed", "arm", "tool_frame", "<origin xyz='1 2 3' rpy='1 2 3'/>") +
      "<link name='tool_frame'/>"));
  ASSERT_EQ(plain.bodies.size(), 1u);
  ASSERT_EQ(framed.bodies.size(), 1u);
  EXPECT_EQ(framed.bodies[0].inertia.mass, plain.bodies[0].inertia.mass);
  EXPECT_EQ(framed.bodies[0].inertia.com, plain.bodies[0].inertia.com);
  EXPECT_EQ(framed.bodies[0].inertia.inertia, plain.bodies[0].inertia.inertia);
}

// Fixed to the welded root, a link is part of the world: its mass drops out
// and its moving children hang from the world at the composed placement.
TEST(Urdf, FixedJointsUnderTheWeldedRootJoinTheWorld) {
  const std::string xml =
      robot("<link name='base'/>" + joint("bolt", "fixed", "base", "plate", "<origin xyz='0 0 1'/>") +
            link("plate", 50.0) +
            joint("j", "continuous", "plate", "arm", "<origin xyz='0 1 0'/>") + link("arm"));
  const RigidTree tree = parse(xml);
  ASSERT_EQ(tree.bodies.size(), 1u);
  EXPECT_EQ(tree.bodies[0].link, "arm");
  EXPECT_EQ(tree.bodies[0].parent, -1);
  expect_near(tree.bodies[0].placement.translation(), Eigen::Vector3d(0, 1, 1), 0.0, "placement");
  EXPECT_EQ(tree.bodies[0].inertia.mass, 1.0);
}

TEST(Urdf, FloatingBaseAddsBodyZero) {
  const std::string xml = robot(link("base", 4.0) + joint("j", "continuous", "base", "arm") +
                                link("arm"));
  const RigidTree welded = parse(xml);
  ASSERT_EQ(welded.bodies.size(), 1u);
  EXPECT_EQ(welded.bodies[0].parent, -1);

  const RigidTree floating = parse(xml, nullptr, true);
  ASSERT_EQ(floating.bodies.size(), 2u);
  EXPECT_EQ(floating.bodies[0].link, "base");
  EXPECT_EQ(floating.bodies[0].joint, "floating_base");
  EXPECT_EQ(floating.bodies[0].type, JointType::kFloating);
  EXPECT_EQ(floating.bodies[0].parent, -1);
  EXPECT_EQ(floating.bodies[0].inertia.mass, 4.0);
  EXPECT_EQ(floating.bodies[1].parent, 0);
}

TEST(Urdf, JointTypes) {
  const std::string xml = robot(
      "<link name='base'/>" +
      joint("r", "revolute", "base", "a",
            "<axis xyz='0 3 4'/><limit lower='-1' upper='1' effort='1' velocity='1'/>") +
      link("a") + joint("c", "continuous", "base", "b") + link("b") +
      joint("p", "planar", "base", "e", "<axis xyz='0 0 1'/>") + link("e") +
      joint("f", "floating", "base", "g") + link("g"));
  std::vector<std::string> notes;
  const RigidTree tree = parse(xml, &notes);
  ASSERT_EQ(tree.bodies.size(), 4u);
  EXPECT_EQ(tree.bodies[0].type, JointType::kRevolute);
  expect_near(tree.bodies[0].axis, Eigen::Vector3d(0, 0.6, 0.8), 1e-16, "normalized axis");
  EXPECT_EQ(tree.bodies[1].type, JointType::kRevolute);
  expect_near(tree.bodies[1].axis, Eigen::Vector3d::UnitX(), 0.0, "URDF default axis");
  EXPECT_EQ(tree.bodies[2].type, JointType::kPlanar);
  expect_near(tree.bodies[2].axis, Eigen::Vector3d::UnitZ(), 0.0, "plane normal");
  EXPECT_EQ(tree.bodies[3].type, JointType::kFloating);
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_EQ(notes[0], "test.urdf: ignored (no effect on the dynamics here): joint limits (1 joint)");
}

TEST(Urdf, BodiesFollowTheFileOrderNotTheAlphabet) {
  const std::string xml = robot("<link name='base'/>" + joint("z_first", "continuous", "base", "z") +
                                link("z") + joint("a_second", "continuous", "base", "a") +
                                link("a") + joint("m_child", "continuous", "z", "m") + link("m"));
  const RigidTree tree = parse(xml);
  ASSERT_EQ(tree.bodies.size(), 3u);
  EXPECT_EQ(tree.bodies[0].link, "z");
  EXPECT_EQ(tree.bodies[1].link, "m");  // depth first
  EXPECT_EQ(tree.bodies[2].link, "a");
  EXPECT_EQ(tree.bodies[1].parent, 0);
}

TEST(Urdf, RotatedInertialFrame) {
  const RigidTree tree = parse(robot(
      "<link name='base'/>" + joint("j", "continuous", "base", "a") +
      "<link name='a'><inertial><origin xyz='1 2 3' rpy='0 0 1.5707963267948966'/><mass "
      "value='1'/><inertia ixx='1' iyy='2' izz='3' ixy='0' ixz='0' iyz='0'/></inertial></link>"));
  expect_near(tree.bodies[0].inertia.com, Eigen::Vector3d(1, 2, 3), 0.0, "com");
  expect_near(tree.bodies[0].inertia.inertia, Eigen::Vector3d(2, 1, 3).asDiagonal().toDenseMatrix(),
              1e-15, "inertia in the link frame");
}

// --- what Drake and MuJoCo accept -------------------------------------------

// An input that must fail, and a fragment of its one-line message.
struct BadCase {
  const char* what;
  std::string xml;
  const char* fragment;
};

// A point-mass link: mass, no inertia about its own centre of mass.
std::string point_mass(const std::string& name, double mass, const std::string& xyz = "0 0 0") {
  return "<link name='" + name + "'><inertial><origin xyz='" + xyz + "'/><mass value='" +
         std::to_string(mass) +
         "'/><inertia ixx='0' iyy='0' izz='0' ixy='0' ixz='0' iyz='0'/></inertial></link>";
}

// urdfdom requires a <limit> with effort and velocity on revolute and
// prismatic joints; limits are not simulated here, and Drake and MuJoCo take
// such joints as unlimited.
TEST(UrdfLenient, RevoluteAndPrismaticJointsNeedNoLimit) {
  std::vector<std::string> notes;
  const RigidTree tree = parse(
      robot("<link name='base'/>" + joint("r", "revolute", "base", "a", "<axis xyz='0 1 0'/>") +
            link("a") + joint("p", "prismatic", "a", "b", "<axis xyz='0 0 1'/>") + link("b") +
            joint("half", "revolute", "b", "c", "<limit lower='-1' upper='1'/>") + link("c")),
      &notes);
  ASSERT_EQ(tree.bodies.size(), 3u);
  EXPECT_EQ(tree.bodies[0].type, JointType::kRevolute);
  expect_near(tree.bodies[0].axis, Eigen::Vector3d::UnitY(), 0.0, "revolute axis");
  EXPECT_EQ(tree.bodies[1].type, JointType::kPrismatic);
  expect_near(tree.bodies[1].axis, Eigen::Vector3d::UnitZ(), 0.0, "prismatic axis");
  EXPECT_EQ(tree.bodies[2].type, JointType::kRevolute);
  // Only the limit the file wrote is reported as ignored, not the ones the
  // loader put in for urdfdom.
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_EQ(notes[0],
            "test.urdf: ignored (no effect on the dynamics here): joint limits (1 joint)");
}

// The rest of what joints carry that is not simulated cannot fail the file
// either: urdfdom rejects a mimic without a joint and a safety controller
// without k_velocity.
TEST(UrdfLenient, MalformedMimicAndSafetyControllerAreIgnored) {
  std::vector<std::string> notes;
  const RigidTree tree =
      parse(robot("<link name='base'/>" +
                  joint("j", "continuous", "base", "a",
                        "<mimic multiplier='2'/><safety_controller k_position='1'/><calibration "
                        "rising='0.1'/>") +
                  link("a")),
            &notes);
  ASSERT_EQ(tree.bodies.size(), 1u);
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_EQ(notes[0],
            "test.urdf: ignored (no effect on the dynamics here): mimic (1 joint), safety "
            "controllers (1 joint), calibration (1 joint)");
}

// Sensor frames and contact points as point masses on fixed joints (a
// humanoid's camera frame of 0.01 kg, a quadruped's feet): welded into the
// parent they are the exact union, like any welded link.
TEST(UrdfLenient, PointMassesWeldIntoTheirParent) {
  const RigidTree tree =
      parse(robot("<link name='base'/>" + joint("j", "continuous", "base", "a") + link("a", 2.0) +
                  joint("camera", "fixed", "a", "camera_frame", "<origin xyz='0 0 0.5'/>") +
                  point_mass("camera_frame", 0.01) +
                  joint("foot", "fixed", "a", "foot_frame", "<origin xyz='1 0 0'/>") +
                  point_mass("foot_frame", 0.5, "0 0 -0.5")));
  ASSERT_EQ(tree.bodies.size(), 1u);
  const RigidInertia& body = tree.bodies[0].inertia;
  EXPECT_DOUBLE_EQ(body.mass, 2.51);
  // COM: (2 * 0 + 0.01 * (0, 0, 0.5) + 0.5 * (1, 0, -0.5)) / 2.51.
  expect_near(body.com, Eigen::Vector3d(0.5, 0, -0.245) / 2.51, 1e-15, "com");
  // The union computed independently: link a's tensor, plus the parallel-axis
  // terms m (|r|^2 I - r r^T) of all three about the new COM.
  Eigen::Matrix3d expected = tensor(1, 2, 3, 0, 0, 0);
  const std::pair<double, Eigen::Vector3d> parts[] = {
      {2.0, Eigen::Vector3d::Zero()}, {0.01, {0, 0, 0.5}}, {0.5, {1, 0, -0.5}}};
  for (const auto& [m, p] : parts) {
    const Eigen::Vector3d r = p - body.com;
    expected += m * (r.squaredNorm() * Eigen::Matrix3d::Identity() - r * r.transpose());
  }
  expect_near(body.inertia, expected, 1e-14, "inertia about the COM");
}

// A root welded to the world drops out whatever its inertia; a floating root
// that is a point (or a rank-one tensor, as a dummy "base" link often is)
// moves with the trunk welded to it, and the two together have inertia.
TEST(UrdfLenient, ASingularRootNeedsInertiaOnlyWithItsWeldedLinks) {
  const std::string dummy_base =
      "<link name='base'><inertial><mass value='1e-6'/><inertia ixx='1e-6' iyy='1e-6' "
      "izz='1e-6' ixy='1e-6' ixz='1e-6' iyz='1e-6'/></inertial></link>";
  const std::string xml =
      robot(dummy_base + joint("bolt", "fixed", "base", "trunk") + link("trunk", 20.0) +
            joint("hip", "continuous", "trunk", "leg") + link("leg"));
  const RigidTree welded = parse(xml);
  ASSERT_EQ(welded.bodies.size(), 1u);
  const RigidTree floating = parse(xml, nullptr, true);
  ASSERT_EQ(floating.bodies.size(), 2u);
  EXPECT_DOUBLE_EQ(floating.bodies[0].inertia.mass, 20.0 + 1e-6);

  // Alone, the same root would have no inertia about two axes.
  EXPECT_NE(
      error_of(robot(dummy_base + joint("hip", "continuous", "base", "leg") + link("leg")), true)
          .find("test.urdf: link 'base': inertia tensor is not positive definite"),
      std::string::npos);
}

// A link whose own tensor is singular (a thin rod about its axis) moves with
// the tip welded to it: the body as a whole has inertia in every direction.
TEST(UrdfLenient, AMovingLinkMayLeanOnItsWeldedLinks) {
  const std::string rod =
      "<link name='rod'><inertial><mass value='0.03'/><inertia ixx='1.2e-4' iyy='1.2e-4' izz='0' "
      "ixy='0' ixz='0' iyz='0'/></inertial></link>";
  const RigidTree tree = parse(
      robot("<link name='base'/>" + joint("j", "continuous", "base", "rod", "<axis xyz='0 1 0'/>") +
            rod + joint("tip", "fixed", "rod", "tip_link") + link("tip_link", 0.01)));
  ASSERT_EQ(tree.bodies.size(), 1u);
  EXPECT_DOUBLE_EQ(tree.bodies[0].inertia.mass, 0.04);
}

// Tensors exported as zero plus rounding noise (1e-20 entries; one principal
// moment comes out slightly negative) are a point mass, not an error.
TEST(UrdfLenient, RoundingNoiseInAPointMassIsZero) {
  const RigidTree tree = parse(robot(
      "<link name='base'/>" + joint("j", "continuous", "base", "a") + link("a") +
      joint("ankle", "fixed", "a", "ankle_link") +
      "<link name='ankle_link'><inertial><origin xyz='0.008 0 0.0553'/><mass value='0.2675'/>"
      "<inertia ixx='0' iyy='0' izz='0' ixy='0' ixz='1.35525e-20' iyz='0'/></inertial></link>"));
  ASSERT_EQ(tree.bodies.size(), 1u);
  EXPECT_DOUBLE_EQ(tree.bodies[0].inertia.mass, 1.2675);
}

// What stays an error: a point mass that moves on its own joint (also with
// only point masses welded to it: a dumbbell has no inertia about its own
// axis), and a tensor that no mass distribution has, welded or not.
TEST(UrdfLenient, GenuinelyBadInertiaIsStillRejected) {
  const std::string base = "<link name='base'/>";
  const std::string not_psd =
      "<inertia ixx='1' iyy='1' izz='1' ixy='2' ixz='0' iyz='0'/>";  // eigenvalues -1, 1, 3
  const std::vector<BadCase> cases = {
      {"moving point mass",
       robot(base + joint("j", "continuous", "base", "a") + point_mass("a", 1.0, "0.5 0 0")),
       "test.urdf: link 'a': inertia tensor is not positive definite (eigenvalues 0, 0, 0); "
       "expected positive principal moments about the centre of mass, since it moves (joint "
       "'j')"},
      {"moving dumbbell",
       robot(base + joint("j", "continuous", "base", "a") + point_mass("a", 1.0) +
             joint("w", "fixed", "a", "b", "<origin xyz='1 0 0'/>") + point_mass("b", 1.0)),
       "test.urdf: link 'a' (with the 1 link welded to it): inertia tensor is not positive "
       "definite (eigenvalues 0, "},
      {"floating point mass", robot(point_mass("base", 1.0)),
       "test.urdf: link 'base': inertia tensor is not positive definite (eigenvalues 0, 0, 0); "
       "expected positive principal moments about the centre of mass, since it moves (joint "
       "'floating_base')"},
      {"welded, not semidefinite",
       robot(base + joint("j", "continuous", "base", "a") + link("a") +
             joint("w", "fixed", "a", "b") + "<link name='b'><inertial><mass value='1'/>" +
             not_psd + "</inertial></link>"),
       "test.urdf: link 'b': inertia tensor is not positive semidefinite (eigenvalues -1, 1, 3); "
       "expected non-negative principal moments about the centre of mass"},
      {"welded to the world, not semidefinite",
       robot("<link name='base'><inertial><mass value='1'/>" + not_psd + "</inertial></link>" +
             joint("j", "continuous", "base", "a") + link("a")),
       "test.urdf: link 'base': inertia tensor is not positive semidefinite (eigenvalues -1, 1, "
       "3)"},
      {"welded, negative mass",
       robot(base + joint("j", "continuous", "base", "a") + link("a") +
             joint("w", "fixed", "a", "b") + link("b", -0.01)),
       "test.urdf: link 'b': mass is -0.01; expected a finite value >= 0"},
      {"welded, NaN inertia",
       robot(base + joint("j", "continuous", "base", "a") + link("a") +
             joint("w", "fixed", "a", "b") +
             "<link name='b'><inertial><mass value='1'/><inertia ixx='nan' iyy='1' izz='1' "
             "ixy='0' ixz='0' iyz='0'/></inertial></link>"),
       "test.urdf: "},
  };
  for (const BadCase& c : cases) {
    SCOPED_TRACE(c.what);
    const std::string message = error_of(c.xml, std::string(c.what) == "floating point mass");
    EXPECT_NE(message.find(c.fragment), std::string::npos) << "message: " << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
  }
}

// --- the note and urdfdom's own output --------------------------------------

TEST(Urdf, NothingIgnoredMeansNoNote) {
  std::vector<std::string> notes;
  parse(robot("<link name='base'/>" + joint("j", "continuous", "base", "a") + link("a")), &notes);
  EXPECT_TRUE(notes.empty());
}

// Junk that urdfdom itself would reject (a mesh without a file name, an
// undefined material) must not fail the file: it does not affect dynamics.
TEST(Urdf, BrokenGeometryIsIgnoredNotRejected) {
  std::vector<std::string> notes;
  const RigidTree tree = parse(
      robot("<link name='base'><visual><geometry><mesh/></geometry><material "
            "name='nowhere'/></visual></link>" +
            joint("j", "continuous", "base", "a", "<dynamics damping='0.3' friction='1'/>") +
            link("a") +
            "<transmission name='t'><joint name='j'/></transmission><gazebo><plugin "
            "filename='package://x/y.so'/></gazebo><material name='m'><color "
            "rgba='bad'/></material>"),
      &notes);
  ASSERT_EQ(tree.bodies.size(), 1u);
  EXPECT_EQ(tree.bodies[0].damping, 0.3);
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_EQ(notes[0],
            "test.urdf: ignored (no effect on the dynamics here): friction (1 joint), "
            "visual/collision geometry (1 link), materials (1), transmissions (1), gazebo blocks "
            "(1)");
}

TEST(Urdf, UrdfdomNeverWritesToStderr) {
  testing::internal::CaptureStderr();
  EXPECT_NE(error_of(read(kBad / "urdf_mass_word.urdf")), "");
  EXPECT_NE(error_of(read(kBad / "urdf_unknown_parent.urdf")), "");
  parse(read(kModels / "tree.urdf"));
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
}

// --- rejections -------------------------------------------------------------

TEST(Urdf, RejectsWithOneLineNamingTheElement) {
  const std::string base = "<link name='base'/>";
  const std::string inertia = "<inertia ixx='1' iyy='1' izz='1' ixy='0' ixz='0' iyz='0'/>";
  const std::vector<BadCase> cases = {
      {"empty", "  \n", "test.urdf: empty file; expected URDF XML with a <robot> element"},
      {"binary", std::string("<robot>\0</robot>", 16),
       "test.urdf:1: not a text file (control byte 0x00)"},
      {"broken XML", "<robot name='r'><link name='a'></robot>", "test.urdf:1:"},
      {"not robot", "<model name='r'/>",
       "test.urdf: the root element is <model>; expected <robot>"},
      {"no element", "<?xml version='1.0'?>", "test.urdf:"},
      {"cycle",
       robot(link("a") + link("b") + joint("ab", "continuous", "a", "b") +
             joint("ba", "continuous", "b", "a")),
       "test.urdf: joints 'ba', 'ab' form a cycle (link 'b' is its own ancestor); expected a tree"},
      {"self loop",
       robot(base + link("a") + joint("j", "continuous", "base", "a") +
             joint("k", "continuous", "a", "a")),
       "test.urdf: link 'a' is the child of two joints ('j' and 'k')"},
      {"self loop without root", robot(link("a") + joint("k", "continuous", "a", "a")),
       "test.urdf: joint 'k' forms a cycle (link 'a' is its own ancestor)"},
      {"two roots", robot(base + link("a") + link("b") + joint("j", "continuous", "base", "a")),
       "Two root links found"},
      {"missing parent", robot(base + link("a") + joint("j", "continuous", "nowhere", "a")),
       "parent link [nowhere] of joint [j] not found"},
      {"missing child", robot(base + joint("j", "continuous", "base", "nowhere")),
       "test.urdf: invalid URDF: "},
      {"unknown type", robot(base + link("a") + joint("j", "ball", "base", "a")),
       "Joint [j] has no known type [ball]"},
      {"zero axis",
       robot(base + link("a") +
             joint("j3", "prismatic", "base", "a",
                   "<axis xyz='0 0 0'/><limit effort='1' velocity='1'/>")),
       "test.urdf: joint 'j3': axis is zero; expected a non-zero vector"},
      {"negative mass",
       robot(base + "<link name='a'><inertial><mass value='-1'/>" + inertia + "</inertial></link>" +
             joint("j", "continuous", "base", "a")),
       "test.urdf: link 'a': mass is -1; expected a finite value >= 0"},
      {"NaN mass",
       robot(base + "<link name='a'><inertial><mass value='nan'/>" + inertia +
             "</inertial></link>" + joint("j", "continuous", "base", "a")),
       "test.urdf: invalid URDF: "},
      {"not PD",
       robot(base +
             "<link name='a'><inertial><mass value='1'/><inertia ixx='1' iyy='1' izz='0' ixy='0' "
             "ixz='0' iyz='0'/></inertial></link>" +
             joint("j", "continuous", "base", "a")),
       "test.urdf: link 'a': inertia tensor is not positive definite (eigenvalues 0, 1, 1)"},
      {"NaN origin",
       robot(base + link("a") + joint("j", "continuous", "base", "a", "<origin xyz='0 0 nan'/>")),
       "Malformed parent origin element for joint [j]"},
      {"massless moving subtree",
       robot(base + "<link name='a'/><link name='b'/>" + joint("j", "continuous", "base", "a") +
             joint("k", "fixed", "a", "b")),
       "test.urdf: link 'a' moves (joint 'j') but carries no mass in its subtree; give it an "
       "<inertial>"},
      {"massless floating root", robot("<link name='base'/>"),
       "test.urdf: link 'base' moves (joint 'floating_base') but carries no mass"},
      {"negative damping",
       robot(base + link("a") + joint("j", "continuous", "base", "a", "<dynamics damping='-1'/>")),
       "test.urdf: joint 'j': damping is -1; expected a finite value >= 0"},
      {"two parents",
       robot(base + link("a") + link("b") + joint("j1", "continuous", "base", "a") +
             joint("j2", "continuous", "a", "b") + joint("j3", "continuous", "b", "a")),
       "test.urdf: link 'a' is the child of two joints ('j1' and 'j3')"},
      {"deep nesting", std::string(5000, '<'), "test.urdf:"},
      {"absurd nesting", robot([] {
         std::string s;
         for (int i = 0; i < 100000; ++i) s += "<a>";
         return s;
       }()),
       "test.urdf:1: XML elements nested more than 100 deep"},
  };
  for (const BadCase& c : cases) {
    SCOPED_TRACE(c.what);
    const std::string message = error_of(c.xml, std::string(c.what) == "massless floating root");
    EXPECT_NE(message.find(c.fragment), std::string::npos) << "message: " << message;
    EXPECT_EQ(message.rfind("test.urdf", 0), 0u) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
  }
}

TEST(Urdf, LoadUrdfRejectsWhatItCannotRead) {
  const std::string missing = (kModels / "no_such_model.urdf").string();
  try {
    load_urdf(missing, {}, nullptr);
    ADD_FAILURE() << "loaded a missing file";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), missing + ": cannot read URDF file (no such file)");
  }
  try {
    load_urdf(kModels.string(), {}, nullptr);
    ADD_FAILURE() << "loaded a directory";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), kModels.string() + ": cannot read URDF file (it is a directory)");
  }
  // Sparse, so the test writes nothing; the size is refused before reading.
  const fs::path huge =
      fs::temp_directory_path() / ("stiffsim_urdf_huge_" + std::to_string(::getpid()) + ".urdf");
  { std::ofstream(huge.string()).put(' '); }
  fs::resize_file(huge, (std::uintmax_t{64} << 20) + 1);
  try {
    load_urdf(huge.string(), {}, nullptr);
    ADD_FAILURE() << "loaded a file over 64 MiB";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(huge.string() + ": URDF file is too large (67108865 bytes"),
              std::string::npos)
        << e.what();
  }
  fs::remove(huge);
}

// The URDF half of the bad-input corpus: the CLI runs these once it loads
// bare URDF files; until then (and also after) the loader is held to the same
// fragments here.
TEST(Urdf, BadInputCorpus) {
  std::istringstream manifest(read(kBad / "expected.txt"));
  int checked = 0;
  for (std::string line; std::getline(manifest, line);) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.rfind("urdf_", 0) != 0) continue;
    const size_t tab = line.find('\t');
    ASSERT_NE(tab, std::string::npos) << line;
    const std::string file = line.substr(0, tab);
    const std::string fragment = line.substr(tab + 1);
    if (fs::path(file).extension() != ".urdf") continue;
    SCOPED_TRACE(file);
    const std::string path = (kBad / file).string();
    std::string message;
    try {
      load_urdf(path, {}, nullptr);
    } catch (const InputError& e) {
      message = e.what();
    }
    EXPECT_EQ(message.rfind(path, 0), 0u) << "message: " << message;
    EXPECT_NE(message.find(fragment), std::string::npos)
        << "message: " << message << "\nexpected: " << fragment;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    ++checked;
  }
  int files = 0;
  for (const auto& entry : fs::directory_iterator(kBad)) {
    const std::string name = entry.path().filename().string();
    files += name.rfind("urdf_", 0) == 0 && entry.path().extension() == ".urdf";
  }
  EXPECT_EQ(checked, files) << "every tests/data/bad/urdf_*.urdf needs a line in expected.txt";
  EXPECT_GE(checked, 15);
}

}  // namespace
}  // namespace stiffsim
