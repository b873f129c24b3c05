#include "stiffsim/model/rnea_derivatives.h"

#include <stdexcept>
#include <string>

#include "stiffsim/model/joints.h"
#include "stiffsim/model/quaternion.h"

namespace stiffsim {
namespace {

using Mat6 = Eigen::Matrix<double, 6, 6>;

// A body-frame motion in world coordinates, about the world origin.
Vec6<double> motion_to_world(const Pose<double>& pose, const Vec6<double>& m) {
  Vec6<double> out;
  const Eigen::Vector3d w = pose.R * m.head<3>();
  out.head<3>() = w;
  out.tail<3>() = pose.R * m.tail<3>() + pose.p.cross(w);
  return out;
}

// The matrix of m -> a x m (cross_motion).
Mat6 motion_cross_matrix(const Vec6<double>& a) {
  Mat6 X;
  const Eigen::Matrix3d W = skew(a.head<3>());
  X.topLeftCorner<3, 3>() = W;
  X.topRightCorner<3, 3>().setZero();
  X.bottomLeftCorner<3, 3>() = skew(a.tail<3>());
  X.bottomRightCorner<3, 3>() = W;
  return X;
}

// The matrix of m -> m x* h for a fixed force h = (n, f).
Mat6 force_cross_matrix(const Vec6<double>& h) {
  Mat6 X;
  const Eigen::Matrix3d F = skew(h.tail<3>());
  X.topLeftCorner<3, 3>() = -skew(h.head<3>());
  X.topRightCorner<3, 3>() = -F;
  X.bottomLeftCorner<3, 3>() = -F;
  X.bottomRightCorner<3, 3>().setZero();
  return X;
}

// Coordinates of a joint's translation part (joints.h: floating and planar
// joints translate first, in the joint frame, then rotate the body).
int translation_coordinates(JointType type) {
  switch (type) {
    case JointType::kFloating:
      return 3;
    case JointType::kPlanar:
      return 2;
    case JointType::kRevolute:
    case JointType::kPrismatic:
      break;
  }
  return 0;
}

}  // namespace

RneaDerivatives::RneaDerivatives(const RigidTree& tree, std::vector<SpatialInertia> inertias,
                                 const Eigen::Vector3d& gravity, const SparseMatrix& K_pattern,
                                 const SparseMatrix& D_pattern)
    : bodies_(tree.bodies), inertia_(std::move(inertias)) {
  const int nb = static_cast<int>(bodies_.size());
  const std::string who = "RneaDerivatives ('" + tree.name + "'): ";
  if (static_cast<int>(inertia_.size()) != nb) {
    throw std::invalid_argument(who + "one spatial inertia per body expected");
  }
  world_acceleration_ << 0.0, 0.0, 0.0, -gravity;
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = bodies_[i];
    if (b.parent >= i || b.parent < -1) {
      throw std::invalid_argument(who + "body '" + b.link + "' comes before its parent");
    }
    const int nqi = joint_nq(b.type), nvi = joint_nv(b.type);
    const int translating = translation_coordinates(b.type);
    q_offset_.push_back(nq_);
    v_offset_.push_back(nv_);
    nq_ += nqi;
    nv_ += nvi;
    for (int k = 0; k < nqi; ++k) q_translates_.push_back(k < translating);
    for (int k = 0; k < nvi; ++k) v_translates_.push_back(k < translating);
  }

  // Every body's related bodies (ancestors, itself, descendants) in ascending
  // order, which is the row order of its columns in K and D; runs of
  // contiguous rows of one kind become one matrix-vector product.
  std::vector<std::vector<int>> descendants(nb);
  for (int i = 0; i < nb; ++i) {
    for (int a = bodies_[i].parent; a >= 0; a = bodies_[a].parent) descendants[a].push_back(i);
  }
  std::vector<int> path;
  run_begin_.push_back(0);
  for (int j = 0; j < nb; ++j) {
    path.clear();
    for (int a = bodies_[j].parent; a >= 0; a = bodies_[a].parent) path.push_back(a);
    auto add = [&](int body, RunKind kind) {
      const int first = v_offset_[body], rows = joint_nv(bodies_[body].type);
      const int begin = run_begin_.back();
      if (static_cast<int>(runs_.size()) > begin && kind != RunKind::kOwn) {
        Run& last = runs_.back();
        if (last.kind == kind && last.first_row + last.rows == first) {
          last.rows += rows;
          return;
        }
      }
      runs_.push_back(Run{first, rows, kind});
    };
    for (auto a = path.rbegin(); a != path.rend(); ++a) add(*a, RunKind::kAncestor);
    add(j, RunKind::kOwn);
    for (int d : descendants[j]) add(d, RunKind::kDescendant);
    run_begin_.push_back(static_cast<int>(runs_.size()));
  }

  // The patterns must be exactly the related pairs, in storage order.
  auto check = [&](const SparseMatrix& P, const char* name, int cols,
                   const std::vector<int>& col_offset, bool positions) {
    const std::string what = who + name + " pattern is not the tree's branch pattern";
    if (P.rows() != nv_ || P.cols() != cols || !P.isCompressed()) throw std::invalid_argument(what);
    long pos = 0;
    for (int j = 0; j < nb; ++j) {
      const int n = positions ? joint_nq(bodies_[j].type) : joint_nv(bodies_[j].type);
      for (int c = col_offset[j]; c < col_offset[j] + n; ++c) {
        if (P.outerIndexPtr()[c] != pos) throw std::invalid_argument(what);
        for (int r = run_begin_[j]; r < run_begin_[j + 1]; ++r) {
          for (int row = runs_[r].first_row; row < runs_[r].first_row + runs_[r].rows; ++row) {
            if (pos >= P.nonZeros() || P.innerIndexPtr()[pos] != row)
              throw std::invalid_argument(what);
            ++pos;
          }
        }
      }
    }
    if (pos != P.nonZeros()) throw std::invalid_argument(what);
    return pos;
  };
  k_nonzeros_ = check(K_pattern, "K", nq_, q_offset_, true);
  d_nonzeros_ = check(D_pattern, "D", nv_, v_offset_, false);

  world_.resize(nb);
  velocity_.resize(nb);
  acceleration_.resize(nb);
  force_.resize(nb);
  inertia_crb_.resize(nb);
  variation_crb_.resize(nb);
  J_.resize(6, nv_);
  force_dv_.resize(6, nv_);
  motion_dv_.resize(12, nv_);
  row_products_.resize(12, nv_);
  twist_dq_.resize(6, nq_);
  force_dq_.resize(6, nq_);
  motion_dq_.resize(12, nq_);
}

void RneaDerivatives::forward_sweep(const ConstVectorRef& q, const ConstVectorRef& v,
                                    const double* acceleration,
                                    const Vec6<double>& world_acceleration) {
  // World velocities and accelerations as in evaluate_forces (a translating
  // part's columns are carried along by the parent: their rate is v_parent x
  // J; a rotating part's by the body: v x J), the composite-inertia
  // ingredients, and per column the non-covariant parts of the derivatives:
  //   dV/dq_c = v_p x t_c,  dA/dq_c = a_p x t_c + v_p x dV/dq_c,
  //   dA/dv_l = (v_own + v_p) x J_l,
  // t_c the twist of a unit dq_c and (v_p, a_p) the motion of the frame the
  // column's part hangs from (the parent, or the intermediate frame after
  // the translation part). The rest of each derivative is J x (.) of the
  // quantity itself, which cancels in J_k^T f below the column's body.
  const int nb = static_cast<int>(bodies_.size());
  for (int i = 0; i < nb; ++i) {
    const TreeBody& b = bodies_[i];
    const int qo = q_offset_[i], vo = v_offset_[i];
    const int nqi = joint_nq(b.type), nvi = joint_nv(b.type);
    const JointMotion<double> jm = joint_motion<double>(b, q.segment(qo, nqi));
    world_[i] = b.parent < 0 ? jm.pose : compose(world_[b.parent], jm.pose);
    const Pose<double>& X = world_[i];
    const Vec6<double> v_parent = b.parent < 0 ? Vec6<double>::Zero() : velocity_[b.parent];
    const Vec6<double> a_parent = b.parent < 0 ? world_acceleration : acceleration_[b.parent];

    for (int l = 0; l < nvi; ++l) J_.col(vo + l) = motion_to_world(X, jm.S.col(l));
    if (b.type == JointType::kFloating) {
      twist_dq_.middleCols<3>(qo) = J_.middleCols<3>(vo);
      // w = 4 / |q|^2 N(q)^T dq: the body-frame turn of a change dq of the
      // raw quaternion (header comment), along the rotation columns of J.
      const Eigen::Vector4d quat = q.segment<4>(qo + 3);
      const Eigen::Matrix<double, 4, 3> N = quaternion_rate_map(quat);
      const double scale = 4.0 / quat.squaredNorm();
      for (int c = 0; c < 4; ++c) {
        twist_dq_.col(qo + 3 + c) = J_.middleCols<3>(vo + 3) * (scale * N.row(c).transpose());
      }
    } else {
      twist_dq_.middleCols(qo, nqi) = J_.middleCols(vo, nvi);
    }

    Vec6<double> u_translation = Vec6<double>::Zero(), u_rotation = Vec6<double>::Zero();
    Vec6<double> a_translation = Vec6<double>::Zero(), a_rotation = Vec6<double>::Zero();
    for (int l = 0; l < nvi; ++l) {
      const bool translates = v_translates_[vo + l];
      (translates ? u_translation : u_rotation) += J_.col(vo + l) * v[vo + l];
      if (acceleration) {
        (translates ? a_translation : a_rotation) += J_.col(vo + l) * acceleration[vo + l];
      }
    }
    const Vec6<double> v_mid = v_parent + u_translation;
    const Vec6<double> a_mid =
        a_parent + a_translation + cross_motion<double>(v_parent, u_translation);
    const Vec6<double> vi = v_mid + u_rotation;
    const Vec6<double> ai = a_mid + a_rotation + cross_motion<double>(vi, u_rotation);
    velocity_[i] = vi;
    acceleration_[i] = ai;

    SpatialInertia world_inertia;
    world_inertia.mass = inertia_[i].mass;
    world_inertia.com = X.R * inertia_[i].com + X.p;
    world_inertia.inertia_com = X.R * inertia_[i].inertia_com * X.R.transpose();
    const Mat6 Y = world_inertia.matrix();
    const Vec6<double> h = Y * vi;
    force_[i] = Y * ai + cross_force<double>(vi, h);
    // B m = Y (m x v) + m x* h + v x* (Y m): how the body's force changes
    // with a velocity change m that is not a rigid transport of the body.
    const Mat6 C = motion_cross_matrix(vi).transpose() * Y;
    variation_crb_[i] = force_cross_matrix(h) - C - C.transpose();
    inertia_crb_[i] = Y;

    for (int l = 0; l < nvi; ++l) {
      const bool translates = v_translates_[vo + l];
      const Vec6<double>& from = translates ? v_parent : v_mid;
      const Vec6<double>& own = translates ? v_mid : vi;
      const Vec6<double> Jl = J_.col(vo + l);
      motion_dv_.col(vo + l).head<6>() = cross_motion<double>(Vec6<double>(own + from), Jl);
      motion_dv_.col(vo + l).tail<6>() = Jl;
    }
    for (int c = 0; c < nqi; ++c) {
      const bool translates = q_translates_[qo + c];
      const Vec6<double>& v_from = translates ? v_parent : v_mid;
      const Vec6<double>& a_from = translates ? a_parent : a_mid;
      const Vec6<double> t = twist_dq_.col(qo + c);
      const Vec6<double> dV = cross_motion<double>(v_from, t);
      motion_dq_.col(qo + c).head<6>() =
          cross_motion<double>(a_from, t) + cross_motion<double>(v_from, dV);
      motion_dq_.col(qo + c).tail<6>() = dV;
    }
  }
}

void RneaDerivatives::backward_sweep() {
  // Composite inertias, variations and forces of every subtree (world
  // coordinates: a child's simply add to its parent's), and with them
  //   rows k:     (Y_crb J_k; B_crb^T J_k), so that below a column's body
  //               dtau_k = row_k . (dA; dV);
  //   columns:    the subtree force derivatives dF/dq_c = Y_crb dA + B_crb dV
  //               + t_c x* f_crb and dF/dv_l = Y_crb dA/dv_l + B_crb J_l,
  //               which reach every ancestor unchanged.
  for (int i = static_cast<int>(bodies_.size()) - 1; i >= 0; --i) {
    const TreeBody& b = bodies_[i];
    const int qo = q_offset_[i], vo = v_offset_[i];
    const Mat6& Y = inertia_crb_[i];
    const Mat6& B = variation_crb_[i];
    for (int l = 0; l < joint_nv(b.type); ++l) {
      const auto Jl = J_.col(vo + l);
      row_products_.col(vo + l).head<6>().noalias() = Y * Jl;
      row_products_.col(vo + l).tail<6>().noalias() = B.transpose() * Jl;
      force_dv_.col(vo + l).noalias() = Y * motion_dv_.col(vo + l).head<6>();
      force_dv_.col(vo + l).noalias() += B * Jl;
    }
    for (int c = 0; c < joint_nq(b.type); ++c) {
      const Vec6<double> t = twist_dq_.col(qo + c);
      force_dq_.col(qo + c) = cross_force<double>(t, force_[i]);
      force_dq_.col(qo + c).noalias() += Y * motion_dq_.col(qo + c).head<6>();
      force_dq_.col(qo + c).noalias() += B * motion_dq_.col(qo + c).tail<6>();
    }
    if (b.parent >= 0) {
      inertia_crb_[b.parent] += Y;
      variation_crb_[b.parent] += B;
      force_[b.parent] += force_[i];
    }
  }
}

void RneaDerivatives::write_values(SparseMatrix* K, SparseMatrix* D) const {
  // One column at a time in storage order (the constructor checked that the
  // patterns list exactly the related rows in this order). F = -tau, hence
  // the signs. Inside a joint, rows of its translation part lie above
  // columns of its rotation part (they see the rotation's dF), all other
  // pairs of the joint are like a descendant's row.
  using Column = Eigen::Map<Eigen::VectorXd>;
  auto write_column = [&](int body, const auto& force_derivative, const auto& motion_derivative,
                          bool column_translates, double* out) {
    for (int r = run_begin_[body]; r < run_begin_[body + 1]; ++r) {
      const Run& run = runs_[r];
      Column values(out, run.rows);
      switch (run.kind) {
        case RunKind::kAncestor:
          values.noalias() = -J_.middleCols(run.first_row, run.rows).transpose() * force_derivative;
          break;
        case RunKind::kDescendant:
          values.noalias() =
              -row_products_.middleCols(run.first_row, run.rows).transpose() * motion_derivative;
          break;
        case RunKind::kOwn:
          for (int k = 0; k < run.rows; ++k) {
            const int row = run.first_row + k;
            values[k] = v_translates_[row] && !column_translates
                            ? -J_.col(row).dot(force_derivative)
                            : -row_products_.col(row).dot(motion_derivative);
          }
          break;
      }
      out += run.rows;
    }
  };
  double* k_values = K->valuePtr();
  double* d_values = D->valuePtr();
  for (int j = 0; j < static_cast<int>(bodies_.size()); ++j) {
    const int qo = q_offset_[j], vo = v_offset_[j];
    for (int c = qo; c < qo + joint_nq(bodies_[j].type); ++c) {
      write_column(j, force_dq_.col(c), motion_dq_.col(c), q_translates_[c],
                   k_values + K->outerIndexPtr()[c]);
    }
    for (int l = vo; l < vo + joint_nv(bodies_[j].type); ++l) {
      write_column(j, force_dv_.col(l), motion_dv_.col(l), v_translates_[l],
                   d_values + D->outerIndexPtr()[l]);
    }
  }
}

void RneaDerivatives::compute(const ConstVectorRef& q, const ConstVectorRef& v,
                              const double* acceleration, SparseMatrix* K, SparseMatrix* D,
                              const Vec6<double>* world_acceleration) {
  if (q.size() != nq_ || v.size() != nv_ || K->nonZeros() != k_nonzeros_ ||
      D->nonZeros() != d_nonzeros_ || K->cols() != nq_ || D->cols() != nv_) {
    throw std::invalid_argument(
        "RneaDerivatives::compute: sizes or patterns differ from the model");
  }
  forward_sweep(q, v, acceleration, world_acceleration ? *world_acceleration : world_acceleration_);
  backward_sweep();
  write_values(K, D);
}

RneaDerivatives make_rnea_derivatives(const ArticulatedSystem& system) {
  const ArticulatedOptions& o = system.options();
  if (!o.bushings.empty()) {
    throw std::invalid_argument("make_rnea_derivatives: '" + system.name() +
                                "' has bushings (compliant formulation)");
  }
  const ForceJacobians& pattern = system.jacobian_pattern();
  return RneaDerivatives(system.tree(), system.model().inertia, o.gravity, pattern.dF_dq,
                         pattern.dF_dv);
}

}  // namespace stiffsim
