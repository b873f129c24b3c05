#pragma once
// A tree of rigid bodies as a URDF describes it once its fixed joints are
// welded (MODELS.md "Articulated bodies from URDF"): immutable model data from
// which both formulations, exact (reduced coordinates) and compliant (free
// bodies joined by bushings), are built.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace stiffsim {

// URDF `continuous` is kRevolute (limits are not simulated); `fixed` joints
// never reach a RigidTree: the loader welds their child into the parent.
enum class JointType { kRevolute, kPrismatic, kFloating, kPlanar };

const char* joint_type_name(JointType type);
int joint_nq(JointType type);  // 1, 1, 7, 3
int joint_nv(JointType type);  // 1, 1, 6, 3

// Mass properties in a body's own (link) frame.
struct RigidInertia {
  double mass = 0.0;
  Eigen::Vector3d com = Eigen::Vector3d::Zero();          // centre of mass
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Zero();      // about the COM, link-frame axes
};

struct TreeBody {
  std::string link;   // URDF link whose frame is this body's frame
  std::string joint;  // URDF joint to the parent ("floating_base" for an added free root)
  int parent = -1;    // index into RigidTree::bodies; -1 is the world
  JointType type = JointType::kRevolute;
  // The joint frame in the parent's frame (the world's for parent -1): the
  // URDF joint origin, composed with the fixed joints welded on the way.
  // At q = 0 the body frame coincides with the joint frame.
  Eigen::Isometry3d placement = Eigen::Isometry3d::Identity();
  // Unit axis in the joint frame (revolute, prismatic; the plane normal of a
  // planar joint); unused for floating joints.
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();
  RigidInertia inertia;  // welded children included
  double damping = 0.0;  // URDF <dynamics damping>: N m s/rad or N s/m
};

struct RigidTree {
  std::string name;  // component name (CSV prefix)
  std::string file;  // source file, for messages
  // Parents come before children (parent < own index).
  std::vector<TreeBody> bodies;
  // The URDF's fixed joints, welded away: kept so that a message about one
  // can say it is fixed rather than unknown.
  std::vector<std::string> fixed_joints;
};

// MODELS.md "Shipped chain models": `links` rods of 0.1 m and 0.1 kg hanging
// along -z, revolute about y, joint i+1 at (0, 0, -0.1) in link i: the tree
// models/chain_N.urdf loads to, built in code for any N.
RigidTree make_chain_tree(int links, const std::string& name = "chain");

// Combines two sets of mass properties given in the same frame.
RigidInertia combine(const RigidInertia& a, const RigidInertia& b);
// `inertia` expressed in a frame whose pose in the new frame is `pose`.
RigidInertia transform(const RigidInertia& inertia, const Eigen::Isometry3d& pose);

}  // namespace stiffsim
