#pragma once
// Scene files (DESIGN.md section 9): a YAML document that names every number
// a run needs. The loader checks the whole document against the schema before
// it builds anything, so a typo or an out-of-range value is reported with the
// file, the line and the key path instead of being silently ignored.

#include <array>
#include <memory>
#include <string>
#include <vector>

#include "stiffsim/integrators/implicit_integrator.h"
#include "stiffsim/integrators/integrator_base.h"
#include "stiffsim/integrators/simulator.h"
#include "stiffsim/scene.h"

namespace stiffsim {

struct SceneConfig {
  std::unique_ptr<Scene> scene;
  SimulationSettings simulation;
  IntegratorSettings integrator;
  ImplicitSettings implicit;
  std::string integrator_name = "vie";
  std::string source;  // the scene file as the user named it
  // Per component of `scene`, its surface triangles in the component's own
  // node numbering (cloth grids and OBJ meshes; empty for ropes). The spring
  // list cannot tell which springs bound a face, and the VTK writer wants
  // faces.
  std::vector<std::vector<std::array<int, 3>>> surfaces;
  // What the loaders ignored or assumed, one line each (e.g. a URDF's joint
  // limits and geometry); the CLI prints them unless --quiet.
  std::vector<std::string> notes;
};

// Loads a scene file after applying `overrides`, each "PATH=VALUE" as given to
// --set: VALUE is parsed as YAML and replaces the value at PATH, where PATH is
// "gravity", "simulation.<key>" or "<component name>.<key>[.<key>]"
// (e.g. "cloth.stretch.k=1e6", "cloth.nodes=[64,64]"). Overrides are applied
// before validation, so an overridden value is checked like any other.
// Throws InputError naming the file (and line, column and key path where
// known) for every problem: unreadable or malformed YAML, unknown keys, values
// out of range, missing meshes or URDFs, and broken URDFs. A bare .urdf file
// is a scene with one exact urdf component named after the file's stem.
SceneConfig load_scene(const std::string& path, const std::vector<std::string>& overrides = {});

// As load_scene, from text in memory. `source_name` names the document in
// messages and as the scene name (its stem); mesh paths are relative to its
// directory.
SceneConfig parse_scene(const std::string& text, const std::string& source_name,
                        const std::vector<std::string>& overrides = {});

// The spellings the scene schema and the CLI accept for the implicit options
// (parse_jacobian_scheme, parse_linear_solver_kind, parse_newton_form and
// parse_error_estimator take them), kept in one place so both stay in step.
std::vector<std::string> jacobian_scheme_names();
std::vector<std::string> linear_solver_names();
std::vector<std::string> newton_form_names();
std::vector<std::string> error_estimator_names();
std::vector<std::string> newton_solve_names();
std::vector<std::string> newton_tolerance_names();
std::vector<std::string> preconditioner_precision_names();

}  // namespace stiffsim
