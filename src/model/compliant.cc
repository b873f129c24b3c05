#include "stiffsim/model/compliant.h"

#include <cmath>

#include "stiffsim/error.h"
#include "stiffsim/model/forward_kinematics.h"
#include "stiffsim/model/quaternion.h"

namespace stiffsim {

std::unique_ptr<ArticulatedSystem> make_compliant(const RigidTree& tree, const ArticulatedOptions& exact,
                                                  const BushingParameters& bushing) {
  for (double x : {bushing.k_lin, bushing.c_lin, bushing.k_ang, bushing.c_ang}) {
    if (!std::isfinite(x) || x < 0.0) {
      throw InputError("component '" + tree.name +
                       "': bushing k_lin, c_lin, k_ang and c_ang must be finite and >= 0");
    }
  }
  // The free bodies would carry neither: refused rather than dropped (the
  // scene loader says so first, with the line).
  if (exact.root_motion) {
    throw InputError("component '" + tree.name +
                     "': root_motion needs the exact formulation (formulation: exact)");
  }
  if (!exact.drives.empty()) {
    throw InputError("component '" + tree.name +
                     "': drives need the exact formulation (formulation: exact)");
  }
  // The exact coordinates place the free bodies (the exact system itself is
  // not built: for a long chain its dense patterns cost more than the run).
  const int nb = static_cast<int>(tree.bodies.size());
  int nq = 0, nv = 0;
  for (const TreeBody& b : tree.bodies) nq += joint_nq(b.type), nv += joint_nv(b.type);
  Eigen::VectorXd q0 = exact.initial_q, v0 = exact.initial_v;
  if (q0.size() == 0) {
    q0 = Eigen::VectorXd::Zero(nq);
    for (int i = 0, qo = 0; i < nb; qo += joint_nq(tree.bodies[i].type), ++i) {
      if (tree.bodies[i].type == JointType::kFloating) q0[qo + 3] = 1.0;
    }
  }
  if (v0.size() == 0) v0 = Eigen::VectorXd::Zero(nv);
  if (q0.size() != nq || v0.size() != nv || !q0.allFinite() || !v0.allFinite()) {
    throw InputError("component '" + tree.name + "': the initial state needs " + std::to_string(nq) +
                     " positions and " + std::to_string(nv) + " velocities, all finite");
  }
  if (!exact.joint_forces.empty() && static_cast<int>(exact.joint_forces.size()) != nb) {
    throw InputError("component '" + tree.name + "': joint forces given for " +
                     std::to_string(exact.joint_forces.size()) + " joints; expected " + std::to_string(nb));
  }
  for (int i = 0, qo = 0; i < nb; qo += joint_nq(tree.bodies[i].type), ++i) {
    if (tree.bodies[i].type != JointType::kFloating) continue;
    const double n = q0.segment<4>(qo + 3).norm();
    if (!(n > 1e-12)) {
      throw InputError("component '" + tree.name + "': joint '" + tree.bodies[i].joint +
                       "': the initial quaternion is zero");
    }
    q0.segment<4>(qo + 3) /= n;
  }
  std::vector<Pose<double>> world;
  std::vector<Vec6<double>> V;
  forward_kinematics(tree, q0, &v0, &world, &V);

  RigidTree forest;
  forest.name = tree.name;
  forest.file = tree.file;
  ArticulatedOptions options;
  options.gravity = exact.gravity;
  options.formulation = "compliant";
  options.initial_q.resize(7 * nb);
  options.initial_v.resize(6 * nb);
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = tree.bodies[i];
    TreeBody free;
    free.link = free.joint = b.link;
    free.parent = -1;
    free.type = JointType::kFloating;
    free.inertia = b.inertia;
    forest.bodies.push_back(free);
    options.initial_q.segment<3>(7 * i) = world[i].p;
    options.initial_q.segment<4>(7 * i + 3) = quaternion_from_rotation(world[i].R);
    // Body coordinates (w, v_origin) to (world origin velocity, body w).
    options.initial_v.segment<3>(6 * i) = world[i].R * V[i].tail<3>();
    options.initial_v.segment<3>(6 * i + 3) = V[i].head<3>();
    if (b.type == JointType::kFloating) continue;
    Bushing bu;
    bu.name = b.joint;
    bu.parent = b.parent;
    bu.child = i;
    bu.type = b.type;
    bu.placement = b.placement;
    bu.axis = b.axis;
    bu.k_lin = bushing.k_lin;
    bu.c_lin = bushing.c_lin;
    bu.k_ang = bushing.k_ang;
    bu.c_ang = bushing.c_ang;
    if (!exact.joint_forces.empty()) bu.joint = exact.joint_forces[i];
    bu.joint.damping += b.damping;
    // The bushing's free coordinate starts at the exact joint's value; the
    // joint spring's rest stays where the scene put it.
    options.bushings.push_back(bu);
  }
  return std::make_unique<ArticulatedSystem>(std::move(forest), std::move(options));
}

}  // namespace stiffsim
