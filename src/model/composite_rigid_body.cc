#include "stiffsim/model/composite_rigid_body.h"

namespace stiffsim {

CompositeRigidBodyData::CompositeRigidBodyData(const ArticulatedModel& model)
    : composite(model.bodies()), transform(model.bodies()), S(model.bodies()) {}

std::vector<int> composite_rigid_body_slots(const ArticulatedModel& model,
                                            const SparseMatrix& pattern) {
  // Pairs (i, j) with j on the path from i to the root, in the order of the
  // algorithm's second sweep; each block entry of M_ji and its mirror M_ij.
  std::vector<int> slots;
  const int nb = model.bodies();
  for (int i = 0; i < nb; ++i) {
    const int ni = joint_nv(model.tree.bodies[i].type);
    for (int j = i; j >= 0; j = model.tree.bodies[j].parent) {
      const int nj = joint_nv(model.tree.bodies[j].type);
      for (int a = 0; a < nj; ++a) {
        for (int b = 0; b < ni; ++b) {
          slots.push_back(slot_of(pattern, model.v_offset[j] + a, model.v_offset[i] + b));
          slots.push_back(slot_of(pattern, model.v_offset[i] + b, model.v_offset[j] + a));
        }
      }
    }
  }
  return slots;
}

void composite_rigid_body(const ArticulatedModel& model, const Eigen::Ref<const Eigen::VectorXd>& q,
                          const std::vector<int>& slots, CompositeRigidBodyData* data,
                          SparseMatrix* M) {
  // Composite rigid body algorithm: the inertia of every subtree in its root
  // body's frame, then M_ji = S_j^T X^T ... X^T Ic_i S_i along the path from i
  // to the root. Only related pairs are visited: the tree's branch sparsity.
  const int nb = model.bodies();
  std::vector<Eigen::Matrix<double, 6, 6>>& Ic = data->composite;
  std::vector<Eigen::Matrix<double, 6, 6>>& X = data->transform;
  std::vector<MotionSubspace<double>>& S = data->S;
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = model.tree.bodies[i];
    const JointMotion<double> jm =
        body_joint_motion<double>(model, i, q.segment(model.q_offset[i], joint_nq(b.type)));
    S[i] = jm.S;
    X[i] = motion_transform_matrix(jm.pose);
    Ic[i] = model.inertia_matrix[i];
  }
  for (int i = nb - 1; i >= 0; --i) {
    const int p = model.tree.bodies[i].parent;
    if (p >= 0) Ic[p].noalias() += X[i].transpose() * Ic[i] * X[i];
  }
  double* values = M->valuePtr();
  std::size_t slot = 0;
  Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, 6> Fm;
  for (int i = 0; i < nb; ++i) {
    Fm = Ic[i] * S[i];
    for (int j = i;;) {
      const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 6, 6> block =
          S[j].transpose() * Fm;
      for (int a = 0; a < block.rows(); ++a) {
        for (int b = 0; b < block.cols(); ++b) {
          values[slots[slot++]] = block(a, b);
          values[slots[slot++]] = block(a, b);
        }
      }
      const int p = model.tree.bodies[j].parent;
      if (p < 0) break;
      Fm = X[j].transpose() * Fm;
      j = p;
    }
  }
}

}  // namespace stiffsim
