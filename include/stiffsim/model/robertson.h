#pragma once
// Robertson's chemical kinetics (Robertson 1966; Hairer & Wanner, Solving
// ODEs II, IV.1), the classic stiff test problem, as a System with only
// miscellaneous states (nq = nv = 0, z = y, nz = 3):
//   y1' = -k1 y1 + k3 y2 y3
//   y2' =  k1 y1 - k3 y2 y3 - k2 y2^2
//   y3' =  k2 y2^2
// from y(0) = (1, 0, 0). The rates span eleven orders of magnitude, so
// explicit methods are held to tiny steps by stability, not accuracy, while
// y1 + y2 + y3 = 1 is a linear invariant every Runge-Kutta method keeps.

#include <string>
#include <vector>

#include "stiffsim/system.h"

namespace stiffsim {

class RobertsonSystem : public System {
 public:
  // Throws InputError unless every rate is finite and >= 0.
  explicit RobertsonSystem(double k1 = 0.04, double k2 = 3e7, double k3 = 1e4);

  // The overloads without a workspace (system.h).
  using System::force_jacobians;
  using System::forces;
  using System::mass_matrix;
  using System::misc_derivatives;

  Dimensions dimensions() const override { return {0, 0, 3}; }
  Capabilities capabilities() const override;
  std::string name() const override { return "robertson"; }
  State initial_state() const override;
  std::vector<std::string> position_names() const override { return {}; }
  std::vector<std::string> velocity_names() const override { return {}; }
  std::vector<std::string> misc_names() const override { return {"y1", "y2", "y3"}; }

  const SparseMatrix& mass_matrix_pattern() const override { return mass_pattern_; }
  void mass_matrix(SystemData&, const ConstVectorRef& q, SparseMatrix* M) const override;
  void forces(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
              const ConstVectorRef& z, VectorRef F) const override;
  void misc_derivatives(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                        const ConstVectorRef& z, VectorRef zdot) const override;
  // Only dfz_dz is non-empty: a dense 3x3 block (its structural zeros are
  // stored so the pattern does not depend on the rates).
  const ForceJacobians& jacobian_pattern() const override { return jacobian_pattern_; }
  void force_jacobians(SystemData&, double t, const ConstVectorRef& q, const ConstVectorRef& v,
                       const ConstVectorRef& z, const JacobianRequest& request,
                       ForceJacobians* J) const override;

  double k1() const { return k1_; }
  double k2() const { return k2_; }
  double k3() const { return k3_; }

 private:
  double k1_, k2_, k3_;
  SparseMatrix mass_pattern_;  // 0 x 0
  ForceJacobians jacobian_pattern_;
  int slots_[3][3];  // slot of dfz_dz(i, j) in the pattern's values
};

}  // namespace stiffsim
