// The compiled half of the Python package `stiffsim` (stiffsim._stiffsim):
// thin wrappers over the library calls the CLI makes. The pure-Python half
// (python/stiffsim/) turns keyword arguments and report files into Python
// shapes; neither half integrates, loads or writes anything itself.

#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/integrators/integrator_factory.h"
#include "stiffsim/io/run_settings.h"
#include "stiffsim/io/scene_drawing.h"
#include "stiffsim/io/scene_run.h"
#include "stiffsim/io/scene_yaml.h"
#include "stiffsim/io/stats_writer.h"
#include "stiffsim/io/trajectory_writer.h"
#include "stiffsim/linalg/blas_threads.h"
#include "stiffsim/reports/reports.h"

namespace py = pybind11;

namespace stiffsim {
namespace {

// Exception types of the module, created once at import; the module keeps
// them alive, so bare handles suffice (static py::objects would be released
// after the interpreter is gone).
py::handle g_input_error;
py::handle g_numerical_failure;

// Sets NumericalFailure(message) with the time and step of the failure as
// the pending Python error.
void set_numerical_failure(const std::string& message, double t, double h) {
  py::object error = g_numerical_failure(message);
  error.attr("t") = t;
  error.attr("h") = h;
  PyErr_SetObject(g_numerical_failure.ptr(), error.ptr());
}

[[noreturn]] void raise_numerical_failure(const std::string& message, double t, double h) {
  set_numerical_failure(message, t, h);
  throw py::error_already_set();
}

// Between steps of a long integration, with the GIL released: checks for a
// pending signal (Ctrl-C) at most every 50 ms, so that the check costs
// nothing next to the steps while an interrupt still lands within a step.
class SignalCheck {
 public:
  // True when a Python handler raised (the error is then pending in
  // `error_`, fetched while the GIL was held).
  bool interrupted() {
    const auto now = std::chrono::steady_clock::now();
    if (now - last_ < std::chrono::milliseconds(50)) return false;
    last_ = now;
    py::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() == 0) return false;
    error_ = std::make_unique<py::error_already_set>();
    return true;
  }
  // Re-raises what the handler raised (KeyboardInterrupt for Ctrl-C); call
  // with the GIL held.
  void rethrow() {
    if (error_) throw py::error_already_set(*error_);
  }

 private:
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
  std::unique_ptr<py::error_already_set> error_;
};

// A loaded scene file. Shared, so that simulators keep it alive.
struct PyScene {
  std::shared_ptr<const SceneConfig> config;
  const Scene& scene() const { return *config->scene; }
};

py::dict dofs_dict(const Dimensions& d) {
  py::dict out;
  out["nq"] = d.nq;
  out["nv"] = d.nv;
  out["nz"] = d.nz;
  return out;
}

// draw_scene() as a list of {name, points (n, 3), segments (m, 2), fixed
// (k,)}, NumPy arrays that matplotlib takes as they are.
py::list scene_drawing(const PyScene& s, double t, const Eigen::VectorXd& x) {
  py::list out;
  for (const ComponentDrawing& d : draw_scene(s.scene(), s.config->surfaces, t, x)) {
    Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> segments(d.segments.size(), 2);
    for (size_t k = 0; k < d.segments.size(); ++k) {
      segments(k, 0) = d.segments[k][0];
      segments(k, 1) = d.segments[k][1];
    }
    py::dict component;
    component["name"] = d.name;
    component["points"] = Eigen::Matrix<double, Eigen::Dynamic, 3>(d.points.transpose());
    component["segments"] = segments;
    component["fixed"] = Eigen::VectorXi(Eigen::Map<const Eigen::VectorXi>(
        d.fixed.data(), static_cast<Eigen::Index>(d.fixed.size())));
    out.append(component);
  }
  return out;
}

py::object json_loads(const std::string& text) {
  return py::module_::import("json").attr("loads")(text);
}

// A scene's integrator, its state and its statistics. The state lives in the
// integrator; q, v and z are returned as copies and set through initialize(),
// which starts a new history (dense output, step-size control, statistics).
class PySimulator {
 public:
  PySimulator(std::shared_ptr<PyScene> scene, const RunOverrides& overrides)
      : scene_(std::move(scene)), settings_(run_settings(*scene_->config, overrides)) {
    integrator_ = make_integrator(settings_.integrator_name, scene_->scene(), settings_.integrator,
                                  settings_.implicit);
    integrator_->initialize(scene_->scene().initial_state());
  }

  double t() const { return state().t; }
  Eigen::VectorXd q() const { return state().q(dims()); }
  Eigen::VectorXd v() const { return state().v(dims()); }
  Eigen::VectorXd z() const { return state().z(dims()); }
  Eigen::VectorXd x() const { return state().x; }

  void set_t(double t) {
    if (!std::isfinite(t)) throw InputError("t: expected a finite time");
    restart(State(t, state().x));
  }
  void set_part(const char* name, int offset, int size, const Eigen::VectorXd& values) {
    if (values.size() != size) {
      throw InputError(std::string(name) + ": expected " + std::to_string(size) + " values, got " +
                       std::to_string(values.size()));
    }
    State s = state();
    s.x.segment(offset, size) = values;
    restart(s);
  }
  void set_q(const Eigen::VectorXd& q) { set_part("q", 0, dims().nq, q); }
  void set_v(const Eigen::VectorXd& v) { set_part("v", dims().nq, dims().nv, v); }
  void set_z(const Eigen::VectorXd& z) { set_part("z", dims().nq + dims().nv, dims().nz, z); }

  // One step ending no later than t_limit; returns the new time.
  double step(double t_limit) {
    if (!(t_limit > state().t)) {
      throw InputError("step: the limit t = " + format(t_limit) +
                       " s is not after t = " + format(state().t) + " s");
    }
    {
      py::gil_scoped_release release;
      try {
        integrator_->step_at_most(t_limit);
      } catch (const IntegrationError& e) {
        failure_ = std::make_unique<IntegrationError>(e);
      }
    }
    raise_failure();
    return state().t;
  }

  // Steps until t reaches t_final exactly, as simulate() does.
  double advance_to(double t_final) {
    if (!std::isfinite(t_final) || t_final < state().t) {
      throw InputError("advance_to: t = " + format(t_final) +
                       " s is before the current t = " + format(state().t) + " s");
    }
    SignalCheck signals;
    {
      py::gil_scoped_release release;
      try {
        while (integrator_->state().t < t_final) {
          integrator_->step_at_most(t_final);
          if (signals.interrupted()) break;
        }
      } catch (const IntegrationError& e) {
        failure_ = std::make_unique<IntegrationError>(e);
      }
    }
    signals.rethrow();
    raise_failure();
    return state().t;
  }

  py::object stats() const { return json_loads(statistics_json(integrator_->statistics())); }
  double energy() const { return scene_->scene().energy(state()); }
  const RunSettings& settings() const { return settings_; }
  const std::shared_ptr<PyScene>& scene() const { return scene_; }
  std::string method() const { return integrator_->method_name(); }

 private:
  const State& state() const { return integrator_->state(); }
  const Dimensions& dims() const { return integrator_->dims(); }
  void restart(const State& s) { integrator_->initialize(s); }
  static std::string format(double value) {
    char text[32];
    std::snprintf(text, sizeof(text), "%g", value);
    return text;
  }
  // With the GIL held: raises NumericalFailure for a failure caught while it
  // was released (a C++ exception must not cross into Python without it).
  void raise_failure() {
    if (!failure_) return;
    const std::unique_ptr<IntegrationError> e = std::move(failure_);
    raise_numerical_failure(e->what(), e->time(), e->step());
  }

  std::shared_ptr<PyScene> scene_;
  RunSettings settings_;
  std::unique_ptr<IntegratorBase> integrator_;
  std::unique_ptr<IntegrationError> failure_;
};

// `stiffsim run`: the same library call, with Ctrl-C checked between steps.
py::object run(const SceneRunRequest& request) {
  SignalCheck signals;
  SceneRunHooks hooks;
  hooks.on_progress = [&](double, double) -> std::string {
    return signals.interrupted() ? "SIGINT" : "";
  };
  std::optional<SceneRunResult> result;
  {
    py::gil_scoped_release release;
    result = run_scene(request, hooks);
  }
  signals.rethrow();
  for (const std::string& e : result->write_errors) throw std::runtime_error(e);
  switch (result->failure) {
    case SceneRunFailure::kNone:
    case SceneRunFailure::kStopped:  // stopped by something other than a signal: not here
      break;
    case SceneRunFailure::kIntegration:
      raise_numerical_failure(result->message, result->failure_time, result->failure_step);
    case SceneRunFailure::kInput:
      throw InputError(result->message);
    case SceneRunFailure::kOther:
      throw std::runtime_error(result->message);
  }
  return json_loads(stats_json(result->summary));
}

int run_report(const std::string& name, const std::string& out_dir, bool quick,
               const std::string& models_dir, bool verbose) {
  ReportOptions options;
  options.quick = quick;
  options.out_dir = out_dir;
  options.models_dir = models_dir;
  options.log = verbose ? &std::cerr : nullptr;
  py::gil_scoped_release release;
  if (name == "precision") return run_precision_report(options);
  if (name == "scaling") return run_scaling_report(options);
  if (name == "stability") return run_stability_report(options);
  throw InputError("unknown report '" + name + "' (expected precision, scaling or stability)");
}

}  // namespace
}  // namespace stiffsim

PYBIND11_MODULE(_stiffsim, m) {
  using namespace stiffsim;
  m.doc() = "Compiled core of the stiffsim package; import stiffsim instead.";

  g_input_error = py::exception<InputError>(m, "InputError", PyExc_ValueError).release();
  g_numerical_failure =
      py::exception<IntegrationError>(m, "NumericalFailure", PyExc_RuntimeError).release();
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const InputError& e) {
      PyErr_SetString(g_input_error.ptr(), e.what());
    } catch (const IntegrationError& e) {
      set_numerical_failure(e.what(), e.time(), e.step());
    }
  });

  m.attr("integrator_names") = integrator_names();
  m.attr("models_dir") = STIFFSIM_MODELS_DIR;
  m.def("set_blas_threads", &set_blas_threads, py::arg("threads"));

  py::class_<PyScene, std::shared_ptr<PyScene>>(m, "Scene")
      .def_property_readonly("name", [](const PyScene& s) { return s.scene().name(); })
      .def_property_readonly("source", [](const PyScene& s) { return s.config->source; })
      .def_property_readonly("dofs",
                             [](const PyScene& s) { return dofs_dict(s.scene().dimensions()); })
      .def_property_readonly("components",
                             [](const PyScene& s) {
                               std::vector<std::string> names;
                               for (int i = 0; i < s.scene().component_count(); ++i) {
                                 names.push_back(s.scene().component(i).name());
                               }
                               return names;
                             })
      .def_property_readonly("columns",
                             [](const PyScene& s) { return trajectory_columns(s.scene()); })
      .def_property_readonly("position_names",
                             [](const PyScene& s) { return s.scene().position_names(); })
      .def_property_readonly("velocity_names",
                             [](const PyScene& s) { return s.scene().velocity_names(); })
      .def_property_readonly("misc_names", [](const PyScene& s) { return s.scene().misc_names(); })
      .def_property_readonly("notes", [](const PyScene& s) { return s.config->notes; })
      .def_property_readonly("integrator",
                             [](const PyScene& s) { return s.config->integrator_name; })
      .def_property_readonly("t_final",
                             [](const PyScene& s) { return s.config->simulation.t_final; })
      .def_property_readonly("step", [](const PyScene& s) { return s.config->integrator.max_step; })
      .def_property_readonly("accuracy",
                             [](const PyScene& s) { return s.config->integrator.accuracy; })
      .def_property_readonly("fixed_step",
                             [](const PyScene& s) { return s.config->integrator.fixed_step; })
      .def("drawing", &scene_drawing, py::arg("t"), py::arg("x"),
           "Points and segments of every drawable component at time t and state x = [q; v; z] "
           "(a row of the trajectory CSV without t): a list of dicts {name, points (n, 3), "
           "segments (m, 2) point indices, fixed: indices of points held by the world}.")
      .def("__repr__", [](const PyScene& s) {
        const Dimensions d = s.scene().dimensions();
        return "<stiffsim.Scene '" + s.scene().name() + "' nq=" + std::to_string(d.nq) +
               " nv=" + std::to_string(d.nv) + " nz=" + std::to_string(d.nz) + ">";
      });

  m.def(
      "_load_scene",
      [](const std::string& path, const std::vector<std::string>& sets) {
        auto scene = std::make_shared<PyScene>();
        scene->config = std::make_shared<SceneConfig>(load_scene(path, sets));
        return scene;
      },
      py::arg("path"), py::arg("sets"));

  py::class_<RunOverrides>(m, "_RunOverrides")
      .def(py::init<>())
      .def_readwrite("integrator", &RunOverrides::integrator)
      .def_readwrite("t_final", &RunOverrides::t_final)
      .def_readwrite("step", &RunOverrides::step)
      .def_readwrite("accuracy", &RunOverrides::accuracy)
      .def_readwrite("sample_period", &RunOverrides::sample_period)
      .def_readwrite("fixed_step", &RunOverrides::fixed_step)
      .def_readwrite("error_estimate", &RunOverrides::error_estimate)
      .def_readwrite("jacobian", &RunOverrides::jacobian)
      .def_readwrite("linear_solver", &RunOverrides::linear_solver)
      .def_readwrite("newton_form", &RunOverrides::newton_form)
      .def_readwrite("error_estimator", &RunOverrides::error_estimator)
      .def_readwrite("newton_solve", &RunOverrides::newton_solve)
      .def_readwrite("newton_tolerance", &RunOverrides::newton_tolerance)
      .def_readwrite("preconditioner_precision", &RunOverrides::preconditioner_precision)
      .def_readwrite("full_newton", &RunOverrides::full_newton)
      .def_readwrite("no_reuse", &RunOverrides::no_reuse);

  py::class_<PySimulator>(m, "_Simulator")
      .def(py::init<std::shared_ptr<PyScene>, const RunOverrides&>(), py::arg("scene"),
           py::arg("overrides"))
      .def_property("t", &PySimulator::t, &PySimulator::set_t)
      .def_property("q", &PySimulator::q, &PySimulator::set_q)
      .def_property("v", &PySimulator::v, &PySimulator::set_v)
      .def_property("z", &PySimulator::z, &PySimulator::set_z)
      .def_property_readonly("x", &PySimulator::x)
      .def_property_readonly("stats", &PySimulator::stats)
      .def_property_readonly("energy", &PySimulator::energy)
      .def_property_readonly("scene", &PySimulator::scene)
      .def_property_readonly("integrator",
                             [](const PySimulator& s) { return s.settings().integrator_name; })
      .def_property_readonly("t_final",
                             [](const PySimulator& s) { return s.settings().simulation.t_final; })
      .def_property_readonly("step_size",
                             [](const PySimulator& s) { return s.settings().integrator.max_step; })
      .def_property_readonly("accuracy",
                             [](const PySimulator& s) { return s.settings().integrator.accuracy; })
      .def_property_readonly(
          "fixed_step", [](const PySimulator& s) { return s.settings().integrator.fixed_step; })
      .def("step", &PySimulator::step, py::arg("t_limit"))
      .def("advance_to", &PySimulator::advance_to, py::arg("t"));

  py::class_<SceneRunRequest>(m, "_RunRequest")
      .def(py::init<>())
      .def_readwrite("scene", &SceneRunRequest::scene)
      .def_readwrite("sets", &SceneRunRequest::sets)
      .def_readwrite("overrides", &SceneRunRequest::overrides)
      .def_readwrite("output", &SceneRunRequest::output)
      .def_readwrite("stats", &SceneRunRequest::stats)
      .def_readwrite("vtk", &SceneRunRequest::vtk);
  m.def("_run", &run, py::arg("request"));
  m.def("_run_report", &run_report, py::arg("name"), py::arg("out_dir"), py::arg("quick"),
        py::arg("models_dir"), py::arg("verbose"));
}
