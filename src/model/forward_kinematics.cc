#include "stiffsim/model/forward_kinematics.h"

#include "stiffsim/model/joints.h"

namespace stiffsim {

void forward_kinematics(const RigidTree& tree, const Eigen::VectorXd& q, const Eigen::VectorXd* v,
                        std::vector<Pose<double>>* world, std::vector<Vec6<double>>* velocities) {
  const int nb = static_cast<int>(tree.bodies.size());
  world->resize(nb);
  if (velocities) velocities->resize(nb);
  int qo = 0, vo = 0;
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = tree.bodies[i];
    const JointMotion<double> jm = joint_motion<double>(b, q.segment(qo, joint_nq(b.type)));
    (*world)[i] = b.parent < 0 ? jm.pose : compose((*world)[b.parent], jm.pose);
    if (velocities) {
      const Vec6<double> vJ = jm.S * v->segment(vo, joint_nv(b.type));
      (*velocities)[i] =
          b.parent < 0
              ? vJ
              : Vec6<double>(motion_to_child<double>(jm.pose, (*velocities)[b.parent]) + vJ);
    }
    qo += joint_nq(b.type);
    vo += joint_nv(b.type);
  }
}

}  // namespace stiffsim
