// SUNDIALS CVODE as a peer integrator (see cvode_peer.h). Built with
// STIFFSIM_HAVE_CVODE when CMake finds SUNDIALS 6; otherwise only the stub at
// the end of this file is compiled.

#include "stiffsim/peers/cvode_peer.h"

#include <stdexcept>

#include "stiffsim/error.h"

#ifdef STIFFSIM_HAVE_CVODE

#include <cvode/cvode.h>
#include <nvector/nvector_serial.h>
#include <sundials/sundials_context.h>
#include <sundials/sundials_version.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunlinsol/sunlinsol_klu.h>
#include <sunmatrix/sunmatrix_dense.h>
#include <sunmatrix/sunmatrix_sparse.h>

#include <Eigen/Cholesky>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <memory>
#include <sstream>
#include <string>
#include <type_traits>

namespace stiffsim {
namespace {

// --- RAII owners of the SUNDIALS objects. Declared in the order of creation,
// so that they are destroyed in reverse (the context last). ---
struct ContextDeleter {
  void operator()(SUNContext ctx) const { SUNContext_Free(&ctx); }
};
struct VectorDeleter {
  void operator()(_generic_N_Vector* v) const { N_VDestroy(v); }
};
struct MatrixDeleter {
  void operator()(_generic_SUNMatrix* A) const { SUNMatDestroy(A); }
};
struct SolverDeleter {
  void operator()(_generic_SUNLinearSolver* LS) const { SUNLinSolFree(LS); }
};
struct CvodeDeleter {
  void operator()(void* mem) const { CVodeFree(&mem); }
};
using ContextPtr = std::unique_ptr<std::remove_pointer_t<SUNContext>, ContextDeleter>;
using VectorPtr = std::unique_ptr<_generic_N_Vector, VectorDeleter>;
using MatrixPtr = std::unique_ptr<_generic_SUNMatrix, MatrixDeleter>;
using SolverPtr = std::unique_ptr<_generic_SUNLinearSolver, SolverDeleter>;
using CvodePtr = std::unique_ptr<void, CvodeDeleter>;

template <class T>
T* check_created(T* p, const char* what) {
  if (p == nullptr) throw std::runtime_error(std::string("CVODE peer: ") + what + " failed");
  return p;
}

// CVodeGetReturnFlagName returns a malloc'ed string: copy it and free it.
std::string flag_name(int flag) {
  char* name = CVodeGetReturnFlagName(flag);
  std::string result = name ? name : ("flag " + std::to_string(flag));
  std::free(name);
  return result;
}

void check_flag(int flag, const char* what) {
  if (flag < 0) {
    throw std::runtime_error(std::string("CVODE peer: ") + what + " returned " + flag_name(flag));
  }
}

// Everything the callbacks need: the system, the work arrays (allocated once)
// and the first exception a system method threw (callbacks must not let it
// unwind through CVODE's C code).
class Problem {
 public:
  Problem(const System& system, bool sparse_jacobian)
      : system_(system),
        data_(system.make_data()),
        d_(system.dimensions()),
        caps_(system.capabilities()),
        sparse_(sparse_jacobian) {
    F_.resize(d_.nv);
    if (d_.nv > 0) {
      M_ = system.mass_matrix_pattern();
      if (!caps_.diagonal_mass_matrix && !use_dense_mass()) sparse_llt_.analyzePattern(M_);
      if (caps_.constant_mass_matrix) {
        // Constant: assembled and factored once (q does not matter).
        const Eigen::VectorXd q0 = Eigen::VectorXd::Zero(d_.nq);
        system_.mass_matrix(*data_, q0, &M_);
        prepare_mass();
        mass_ready_ = true;
      }
    }
    if (sparse_) build_jacobian_pattern();
  }

  const Dimensions& dims() const { return d_; }
  long jacobian_nonzeros() const { return static_cast<long>(Jx_.nonZeros()); }
  std::exception_ptr error() const { return error_; }
  std::string error_message() const { return error_message_; }

  // x' = f(t, x). Returns 0, 1 (recoverable: non-finite values, CVODE retries
  // with a smaller step) or -1 (the system threw).
  int rhs(double t, const double* x, double* xdot) {
    try {
      const int nq = d_.nq, nv = d_.nv, nz = d_.nz;
      Eigen::Map<const Eigen::VectorXd> X(x, d_.nx());
      Eigen::Map<Eigen::VectorXd> Xdot(xdot, d_.nx());
      const auto q = X.segment(0, nq);
      const auto v = X.segment(nq, nv);
      const auto z = X.segment(nq + nv, nz);
      if (caps_.identity_velocity_map) {
        Xdot.segment(0, nq) = v;
      } else {
        system_.map_velocity_to_qdot(q, v, Xdot.segment(0, nq));
      }
      if (nv > 0) {
        system_.forces(*data_, t, q, v, z, F_);
        if (!caps_.constant_mass_matrix || !mass_ready_) {
          system_.mass_matrix(*data_, q, &M_);
          prepare_mass();
        }
        auto vdot = Xdot.segment(nq, nv);
        if (caps_.diagonal_mass_matrix) {
          vdot = F_.cwiseProduct(inverse_mass_diagonal_);
        } else if (use_dense_mass()) {
          vdot = dense_llt_.solve(F_);
        } else {
          vdot = sparse_llt_.solve(F_);
        }
      }
      if (nz > 0) system_.misc_derivatives(*data_, t, q, v, z, Xdot.segment(nq + nv, nz));
      return Xdot.allFinite() ? 0 : 1;
    } catch (const std::exception& e) {
      remember(std::current_exception(), e.what());
      return -1;
    } catch (...) {
      remember(std::current_exception(), "unknown exception");
      return -1;
    }
  }

  // The complete analytic Jacobian of rhs() in CSC form into J (only for
  // N = I and a constant diagonal mass matrix).
  int jacobian(double t, const double* x, SUNMatrix J) {
    try {
      const int nq = d_.nq, nv = d_.nv, nz = d_.nz;
      Eigen::Map<const Eigen::VectorXd> X(x, d_.nx());
      const auto q = X.segment(0, nq);
      const auto v = X.segment(nq, nv);
      const auto z = X.segment(nq + nv, nz);
      JacobianRequest request;
      request.definite = false;
      request.complete = true;
      system_.force_jacobians(*data_, t, q, v, z, request, &fj_);

      set_zero_keep_pattern(&Jx_);
      double* values = Jx_.valuePtr();
      for (int slot : identity_slots_) values[slot] = 1.0;
      // Velocity rows: M^-1 times the force Jacobians (a row scaling).
      scatter_scaled(fj_.dF_dq, slots_[0], true, values);
      scatter_scaled(fj_.dF_dv, slots_[1], true, values);
      scatter_scaled(fj_.dF_dz, slots_[2], true, values);
      scatter_scaled(fj_.dfz_dq, slots_[3], false, values);
      scatter_scaled(fj_.dfz_dv, slots_[4], false, values);
      scatter_scaled(fj_.dfz_dz, slots_[5], false, values);
      if (!Eigen::Map<const Eigen::VectorXd>(values, Jx_.nonZeros()).allFinite()) return 1;

      // CVODE's SUNMatScaleAddI may have touched the structure of the matrix
      // it hands back: write the whole CSC matrix every time.
      const sunindextype nnz = Jx_.nonZeros();
      if (SM_NNZ_S(J) < nnz && SUNSparseMatrix_Reallocate(J, nnz) != SUNMAT_SUCCESS) return -1;
      sunindextype* colptrs = SM_INDEXPTRS_S(J);
      sunindextype* rowvals = SM_INDEXVALS_S(J);
      double* data = SM_DATA_S(J);
      for (int c = 0; c <= Jx_.cols(); ++c) colptrs[c] = Jx_.outerIndexPtr()[c];
      for (sunindextype k = 0; k < nnz; ++k) {
        rowvals[k] = Jx_.innerIndexPtr()[k];
        data[k] = values[k];
      }
      return 0;
    } catch (const std::exception& e) {
      remember(std::current_exception(), e.what());
      return -1;
    } catch (...) {
      remember(std::current_exception(), "unknown exception");
      return -1;
    }
  }

 private:
  bool use_dense_mass() const { return d_.nv <= 32; }

  void prepare_mass() {
    if (caps_.diagonal_mass_matrix) {
      inverse_mass_diagonal_ = M_.diagonal().cwiseInverse();
    } else if (use_dense_mass()) {
      dense_M_ = Eigen::MatrixXd(M_);
      dense_llt_.compute(dense_M_);
      if (dense_llt_.info() != Eigen::Success) {
        throw std::runtime_error("mass matrix not positive definite");
      }
    } else {
      sparse_llt_.factorize(M_);
      if (sparse_llt_.info() != Eigen::Success) {
        throw std::runtime_error("mass matrix not positive definite");
      }
    }
  }

  // x = (q, v, z): rows and columns of the blocks in the full Jacobian.
  void build_jacobian_pattern() {
    const int nq = d_.nq, nv = d_.nv, nz = d_.nz, n = d_.nx();
    fj_ = system_.jacobian_pattern();
    PatternBuilder b(n, n);
    for (int i = 0; i < nv; ++i) b.add(i, nq + i);
    // The diagonal, stored explicitly, so that CVODE's I - gamma J keeps
    // the structure.
    b.add_diagonal(0, n);
    const SparseMatrix* parts[6] = {&fj_.dF_dq, &fj_.dF_dv, &fj_.dF_dz,
                                    &fj_.dfz_dq, &fj_.dfz_dv, &fj_.dfz_dz};
    const int row0[6] = {nq, nq, nq, nq + nv, nq + nv, nq + nv};
    const int col0[6] = {0, nq, nq + nv, 0, nq, nq + nv};
    for (int k = 0; k < 6; ++k) b.add_pattern(*parts[k], row0[k], col0[k]);
    Jx_ = b.build();
    for (int i = 0; i < nv; ++i) identity_slots_.push_back(slot_of(Jx_, i, nq + i));
    for (int k = 0; k < 6; ++k) {
      slots_[k] = parts[k]->nonZeros() > 0 ? slots_in(Jx_, *parts[k], row0[k], col0[k])
                                           : std::vector<int>{};
    }
    (void)nz;
  }

  void scatter_scaled(const SparseMatrix& part, const std::vector<int>& slots, bool by_mass,
                      double* values) const {
    const double* v = part.valuePtr();
    const int* rows = part.innerIndexPtr();
    for (std::size_t k = 0; k < slots.size(); ++k) {
      values[slots[k]] += by_mass ? v[k] * inverse_mass_diagonal_[rows[k]] : v[k];
    }
  }

  void remember(std::exception_ptr e, const char* what) {
    if (!error_) {
      error_ = e;
      error_message_ = what;
    }
  }

  const System& system_;
  const std::unique_ptr<SystemData> data_;
  const Dimensions d_;
  const Capabilities caps_;
  const bool sparse_;
  Eigen::VectorXd F_;
  SparseMatrix M_;
  bool mass_ready_ = false;
  Eigen::VectorXd inverse_mass_diagonal_;
  Eigen::MatrixXd dense_M_;
  Eigen::LLT<Eigen::MatrixXd> dense_llt_;
  Eigen::SimplicialLLT<SparseMatrix> sparse_llt_;
  // Sparse Jacobian path.
  ForceJacobians fj_;
  SparseMatrix Jx_;  // pattern and values of the full Jacobian in x
  std::vector<int> identity_slots_;
  std::vector<int> slots_[6];
  std::exception_ptr error_;
  std::string error_message_;
};

int rhs_callback(sunrealtype t, N_Vector x, N_Vector xdot, void* user_data) {
  return static_cast<Problem*>(user_data)->rhs(t, N_VGetArrayPointer(x), N_VGetArrayPointer(xdot));
}

int jacobian_callback(sunrealtype t, N_Vector x, N_Vector fx, SUNMatrix J, void* user_data,
                      N_Vector tmp1, N_Vector tmp2, N_Vector tmp3) {
  (void)fx, (void)tmp1, (void)tmp2, (void)tmp3;
  return static_cast<Problem*>(user_data)->jacobian(t, N_VGetArrayPointer(x), J);
}

// Keeps CVODE's last error message (instead of printing it to stderr).
void error_callback(int error_code, const char* module, const char* function, char* msg,
                    void* user_data) {
  (void)error_code;
  auto* last = static_cast<std::string*>(user_data);
  *last = std::string(module ? module : "CVODE") + " " + (function ? function : "") + ": " +
          (msg ? msg : "");
}

}  // namespace

bool cvode_available() { return true; }

PeerRun run_cvode(const System& system, const State& initial, const std::vector<double>& sample_times,
                  const CvodeOptions& options) {
  const Dimensions d = system.dimensions();
  const Capabilities caps = system.capabilities();
  if (initial.x.size() != d.nx()) {
    throw std::invalid_argument("run_cvode: the initial state has " +
                                std::to_string(initial.x.size()) + " values, the system " +
                                std::to_string(d.nx()));
  }
  if (d.nx() == 0) throw std::invalid_argument("run_cvode: the system has no state");
  double previous = initial.t;
  for (double t : sample_times) {
    if (!(t > previous)) {
      throw std::invalid_argument("run_cvode: sample times must be ascending and after the initial time");
    }
    previous = t;
  }
  if (!(options.relative_tolerance > 0) || !(options.absolute_tolerance > 0) ||
      options.max_order < 1 || options.max_order > 5 || options.max_step < 0) {
    throw std::invalid_argument("run_cvode: tolerances must be positive, max_order in 1..5, max_step >= 0");
  }

  const bool sparse = caps.identity_velocity_map && caps.diagonal_mass_matrix &&
                      caps.constant_mass_matrix && caps.analytic_jacobians && d.nq == d.nv;
  Problem problem(system, sparse);
  const sunindextype n = d.nx();

  SUNContext raw_ctx = nullptr;
  if (SUNContext_Create(nullptr, &raw_ctx) != 0 || raw_ctx == nullptr) {
    throw std::runtime_error("CVODE peer: SUNContext_Create failed");
  }
  ContextPtr ctx(raw_ctx);
  VectorPtr y(check_created(N_VNew_Serial(n, ctx.get()), "N_VNew_Serial"));
  std::copy(initial.x.data(), initial.x.data() + n, N_VGetArrayPointer(y.get()));

  MatrixPtr A;
  SolverPtr LS;
  if (sparse) {
    A.reset(check_created(SUNSparseMatrix(n, n, problem.jacobian_nonzeros(), CSC_MAT, ctx.get()),
                          "SUNSparseMatrix"));
    LS.reset(check_created(SUNLinSol_KLU(y.get(), A.get(), ctx.get()), "SUNLinSol_KLU"));
  } else {
    A.reset(check_created(SUNDenseMatrix(n, n, ctx.get()), "SUNDenseMatrix"));
    LS.reset(check_created(SUNLinSol_Dense(y.get(), A.get(), ctx.get()), "SUNLinSol_Dense"));
  }

  CvodePtr mem(check_created(CVodeCreate(CV_BDF, ctx.get()), "CVodeCreate"));
  std::string last_error;
  check_flag(CVodeSetErrHandlerFn(mem.get(), error_callback, &last_error), "CVodeSetErrHandlerFn");
  check_flag(CVodeInit(mem.get(), rhs_callback, initial.t, y.get()), "CVodeInit");
  check_flag(CVodeSetUserData(mem.get(), &problem), "CVodeSetUserData");
  check_flag(CVodeSStolerances(mem.get(), options.relative_tolerance, options.absolute_tolerance),
             "CVodeSStolerances");
  check_flag(CVodeSetLinearSolver(mem.get(), LS.get(), A.get()), "CVodeSetLinearSolver");
  if (sparse) check_flag(CVodeSetJacFn(mem.get(), jacobian_callback), "CVodeSetJacFn");
  check_flag(CVodeSetMaxNumSteps(mem.get(), 10000000L), "CVodeSetMaxNumSteps");
  check_flag(CVodeSetMaxOrd(mem.get(), options.max_order), "CVodeSetMaxOrd");
  if (options.max_step > 0) check_flag(CVodeSetMaxStep(mem.get(), options.max_step), "CVodeSetMaxStep");

  PeerRun run;
  char version[64] = "6";
  SUNDIALSGetVersion(version, sizeof(version));
  std::ostringstream settings;
  settings << "CVODE " << version << " BDF (max order " << options.max_order << "), Newton, ";
  if (sparse) {
    run.method = "cvode-bdf-klu";
    settings << "KLU with analytic sparse Jacobian (complete, nnz " << problem.jacobian_nonzeros()
             << ")";
  } else {
    run.method = "cvode-bdf-dense";
    settings << "dense LU with CVODE's difference-quotient Jacobian (n " << n << ")";
  }
  settings << ", rtol " << format_number(options.relative_tolerance) << ", atol "
           << format_number(options.absolute_tolerance);
  if (options.max_step > 0) settings << ", max step " << format_number(options.max_step);
  if (caps.has_quaternions) {
    settings << ", quaternions normalized in the stored samples only (CVODE's state is not projected)";
  }
  run.settings = settings.str();

  using Clock = std::chrono::steady_clock;
  Clock::duration elapsed{0};
  Eigen::VectorXd sample(n);
  for (double tout : sample_times) {
    sunrealtype tret = initial.t;
    const Clock::time_point start = Clock::now();
    const int flag = CVode(mem.get(), tout, y.get(), &tret, CV_NORMAL);
    elapsed += Clock::now() - start;
    if (flag < 0) {
      run.failed = true;
      std::ostringstream message;
      message << "CVODE flag " << flag_name(flag) << " at t = " << tret;
      if (problem.error()) message << ": the system threw: " << problem.error_message();
      if (!last_error.empty()) message << " (" << last_error << ")";
      run.message = message.str();
      break;
    }
    std::copy(N_VGetArrayPointer(y.get()), N_VGetArrayPointer(y.get()) + n, sample.data());
    if (caps.has_quaternions) system.project_positions(sample.segment(0, d.nq));
    run.times.push_back(tret);
    run.samples.push_back(sample);
  }
  run.wall_seconds = std::chrono::duration<double>(elapsed).count();

  long value = 0;
  if (CVodeGetNumSteps(mem.get(), &value) == CV_SUCCESS) run.steps = value;
  long rhs = 0, lin_rhs = 0;
  CVodeGetNumRhsEvals(mem.get(), &rhs);
  CVodeGetNumLinRhsEvals(mem.get(), &lin_rhs);
  run.rhs_evaluations = rhs + lin_rhs;
  if (CVodeGetNumJacEvals(mem.get(), &value) == CV_SUCCESS) run.jacobian_evaluations = value;
  if (CVodeGetNumLinSolvSetups(mem.get(), &value) == CV_SUCCESS) run.linear_setups = value;
  return run;
}

}  // namespace stiffsim

#else  // !STIFFSIM_HAVE_CVODE

namespace stiffsim {

bool cvode_available() { return false; }

PeerRun run_cvode(const System& system, const State& initial, const std::vector<double>& sample_times,
                  const CvodeOptions& options) {
  (void)system, (void)initial, (void)sample_times, (void)options;
  throw std::runtime_error("stiffsim was built without SUNDIALS");
}

}  // namespace stiffsim

#endif  // STIFFSIM_HAVE_CVODE
