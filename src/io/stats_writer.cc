#include "stiffsim/io/stats_writer.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "stiffsim/error.h"
#include "stiffsim/io/atomic_file.h"
#include "stiffsim/linalg/blas_kernels.h"
#include "stiffsim/linalg/blas_threads.h"

namespace stiffsim {
namespace {

// ordered_json keeps the keys in the order a reader expects (scene first).
using json = nlohmann::ordered_json;

// nlohmann would write NaN as null too, but only as a side effect of its
// serializer; being explicit keeps the file valid JSON whatever the settings.
json number(double value) { return std::isfinite(value) ? json(value) : json(nullptr); }

// Every field of IntegratorStatistics, by its exact name. A field added to
// the struct must be added here too: the static_assert below stops the build
// until it is, so the stats file never silently misses a counter.
json statistics_object(const IntegratorStatistics& s) {
  static_assert(sizeof(IntegratorStatistics) == 83 * 8,
                "IntegratorStatistics changed: update statistics_object()");
  json j;
  j["steps_taken"] = s.steps_taken;
  j["derivative_evaluations"] = s.derivative_evaluations;
  j["derivative_evaluations_for_jacobian"] = s.derivative_evaluations_for_jacobian;
  j["jacobian_evaluations"] = s.jacobian_evaluations;
  j["iteration_matrix_factorizations"] = s.iteration_matrix_factorizations;
  j["newton_raphson_iterations"] = s.newton_raphson_iterations;
  j["error_estimator_derivative_evaluations"] = s.error_estimator_derivative_evaluations;
  j["error_estimator_derivative_evaluations_for_jacobian"] =
      s.error_estimator_derivative_evaluations_for_jacobian;
  j["error_estimator_jacobian_evaluations"] = s.error_estimator_jacobian_evaluations;
  j["error_estimator_iteration_matrix_factorizations"] =
      s.error_estimator_iteration_matrix_factorizations;
  j["error_estimator_newton_raphson_iterations"] = s.error_estimator_newton_raphson_iterations;
  j["substep_failures"] = s.substep_failures;
  j["step_shrinkages_from_substep_failures"] = s.step_shrinkages_from_substep_failures;
  j["step_shrinkages_from_error_control"] = s.step_shrinkages_from_error_control;
  j["smallest_adapted_step_size_taken"] = number(s.smallest_adapted_step_size_taken);
  j["largest_step_size_taken"] = number(s.largest_step_size_taken);
  j["actual_initial_step_size_taken"] = number(s.actual_initial_step_size_taken);
  j["newton_solves"] = s.newton_solves;
  j["newton_trials"] = s.newton_trials;
  j["line_search_backtracks"] = s.line_search_backtracks;
  j["energy_guard_checks"] = s.energy_guard_checks;
  j["energy_guard_rejections"] = s.energy_guard_rejections;
  j["extrapolation_rejections"] = s.extrapolation_rejections;
  j["predictor_declined"] = s.predictor_declined;
  j["step_guesses_corrected"] = s.step_guesses_corrected;
  j["merit_damping_evaluations"] = s.merit_damping_evaluations;
  j["velocity_map_evaluations"] = s.velocity_map_evaluations;
  j["mass_matrix_assemblies"] = s.mass_matrix_assemblies;
  j["symbolic_analyses"] = s.symbolic_analyses;
  j["linear_solves"] = s.linear_solves;
  j["dense_output_evaluations"] = s.dense_output_evaluations;
  j["jacobian_approximated_terms"] = s.jacobian_approximated_terms;
  j["iteration_matrix_nonzeros"] = s.iteration_matrix_nonzeros;
  j["factor_nonzeros"] = s.factor_nonzeros;
  j["krylov_first_solves"] = s.krylov_first_solves;
  j["fresh_first_solves"] = s.fresh_first_solves;
  j["krylov_newton_failures"] = s.krylov_newton_failures;
  j["fresh_rescues"] = s.fresh_rescues;
  j["last_rung_extensions"] = s.last_rung_extensions;
  j["exact_hessian_factorizations"] = s.exact_hessian_factorizations;
  j["exact_hessian_indefinite"] = s.exact_hessian_indefinite;
  j["root_checks"] = s.root_checks;
  j["root_checks_unfinished"] = s.root_checks_unfinished;
  j["largest_root_distance_ratio"] = number(s.largest_root_distance_ratio);
  j["covered_coupling_factorizations"] = s.covered_coupling_factorizations;
  j["refined_solves"] = s.refined_solves;
  j["refined_solve_products"] = s.refined_solve_products;
  j["refined_solve_fallbacks"] = s.refined_solve_fallbacks;
  j["newton_tolerance_from_step_error"] = s.newton_tolerance_from_step_error;
  j["newton_tolerance_narrowed"] = s.newton_tolerance_narrowed;
  j["krylov_solves"] = s.krylov_solves;
  j["krylov_iterations"] = s.krylov_iterations;
  j["krylov_max_iterations"] = s.krylov_max_iterations;
  j["krylov_failures"] = s.krylov_failures;
  j["krylov_chord_convergences"] = s.krylov_chord_convergences;
  j["krylov_update_convergences"] = s.krylov_update_convergences;
  j["krylov_chord_starts"] = s.krylov_chord_starts;
  j["fresh_chord_tests"] = s.fresh_chord_tests;
  j["fresh_chord_convergences"] = s.fresh_chord_convergences;
  j["fresh_finishing_solves"] = s.fresh_finishing_solves;
  j["fresh_finishing_convergences"] = s.fresh_finishing_convergences;
  j["fresh_near_root_finishes"] = s.fresh_near_root_finishes;
  j["krylov_stalled_solves"] = s.krylov_stalled_solves;
  j["direct_stalled_trials"] = s.direct_stalled_trials;
  j["largest_final_residual_ratio"] = number(s.largest_final_residual_ratio);
  j["krylov_rate_test_vetoes"] = s.krylov_rate_test_vetoes;
  j["krylov_eisenstat_walker_solves"] = s.krylov_eisenstat_walker_solves;
  j["krylov_stale_solves_abandoned"] = s.krylov_stale_solves_abandoned;
  j["single_precision_solves"] = s.single_precision_solves;
  j["single_precision_declined"] = s.single_precision_declined;
  j["single_precision_factorizations"] = s.single_precision_factorizations;
  j["chord_solves"] = s.chord_solves;
  j["factorizations_ladder"] = s.factorizations_ladder;
  j["recursive_factorizations"] = s.recursive_factorizations;
  j["factorizations_first"] = s.factorizations_first;
  j["factorizations_cost_model"] = s.factorizations_cost_model;
  j["factorizations_krylov_failed"] = s.factorizations_krylov_failed;
  j["jacobian_seconds"] = number(s.jacobian_seconds);
  j["assembly_seconds"] = number(s.assembly_seconds);
  j["factorization_seconds"] = number(s.factorization_seconds);
  j["solve_seconds"] = number(s.solve_seconds);
  j["derivative_seconds"] = number(s.derivative_seconds);
  j["krylov_seconds"] = number(s.krylov_seconds);
  return j;
}

json integrator_json(const IntegratorReport& r) {
  json j;
  j["method"] = r.method;
  j["mode"] = r.mode;
  j["error_estimate"] = r.error_estimate;
  j["extrapolated"] = r.extrapolated;
  if (!r.error_estimator.empty()) j["error_estimator"] = r.error_estimator;
  if (r.jacobian_colours > 0) j["jacobian_colours"] = r.jacobian_colours;
  j["jacobian_scheme"] = r.jacobian_scheme;
  j["newton_form"] = r.newton_form;
  if (!r.newton_solve.empty()) {
    j["newton_solve"] = {{"chosen", r.newton_solve}, {"reason", r.newton_solve_reason}};
  }
  if (!r.preconditioner_precision.empty()) {
    j["preconditioner_precision"] = r.preconditioner_precision;
  }
  j["linear_solver"] = {{"chosen", r.linear_solver},
                        {"reason", r.linear_solver_reason},
                        {"fallback", r.linear_solver_fallback}};
  return j;
}

}  // namespace

std::string statistics_json(const IntegratorStatistics& statistics) {
  return statistics_object(statistics).dump();
}

std::string stats_json(const RunSummary& s) {
  json j;
  j["scene"] = s.scene;
  j["dofs"] = {{"nq", s.dofs.nq}, {"nv", s.dofs.nv}, {"nz", s.dofs.nz}};
  j["integrator"] = integrator_json(s.report);
  j["settings"] = {{"accuracy", number(s.accuracy)},
                   {"step", number(s.step)},
                   {"sample_period", number(s.sample_period)}};
  j["nnz"] = {{"iteration_matrix", s.statistics.iteration_matrix_nonzeros},
              {"factor", s.statistics.factor_nonzeros}};
  j["wall_time_s"] = {{"total", number(s.wall_seconds)},
                      {"jacobian", number(s.statistics.jacobian_seconds)},
                      {"assembly", number(s.statistics.assembly_seconds)},
                      {"factorization", number(s.statistics.factorization_seconds)},
                      {"solve", number(s.statistics.solve_seconds)},
                      {"derivative", number(s.statistics.derivative_seconds)}};
  j["statistics"] = statistics_object(s.statistics);
  // The process's BLAS as the sparse solvers left it (linalg/blas_threads.h,
  // linalg/blas_kernels.h): what every factorization time above ran on.
  j["blas"] = {{"threads", current_blas_threads()}, {"kernels", blas_kernels_note()}};
  j["skipped"] = s.report.skipped;
  j["energy"] = {{"start", number(s.energy_start)}, {"end", number(s.energy_end)}};
  j["samples"] = s.samples;
  j["t_final"] = number(s.t_final);
  j["t_reached"] = number(s.t_reached);
  j["stopped_early"] = s.stopped_early;
  j["stop_reason"] = s.stopped_early ? json(s.stop_reason) : json(nullptr);
  return j.dump(2) + "\n";
}

StatsWriter::StatsWriter(std::string path) : path_(std::move(path)), temp_path_(path_ + ".tmp") {
  std::FILE* file = std::fopen(temp_path_.c_str(), "wb");
  if (file == nullptr) {
    throw InputError(path_ + ": cannot create the stats file (" + std::strerror(errno) + ")");
  }
  std::fclose(file);
  pending_ = true;
}

StatsWriter::~StatsWriter() {
  if (pending_) std::remove(temp_path_.c_str());
}

void StatsWriter::write(const RunSummary& summary) {
  if (!pending_) throw std::logic_error("StatsWriter::write called twice");
  // The temporary made at construction is "<path>.tmp", the one
  // write_file_atomically() writes and commits.
  write_file_atomically(path_, stats_json(summary));
  pending_ = false;
}

}  // namespace stiffsim
