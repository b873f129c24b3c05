// Drops the spinning box of models/free_body.yaml in gravity and checks the
// closed form: the body's origin (its centre of mass) falls as -g t^2 / 2
// whatever the spin does, and the energy stays what it was. RK45 integrates a
// quadratic in t exactly, so only the error control's round-off is left.
//
// Usage: free_fall <models dir>. Exit 0 when every check holds.

#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "stiffsim/error.h"
#include "stiffsim/integrators/integrator_factory.h"
#include "stiffsim/io/run_settings.h"
#include "stiffsim/io/scene_yaml.h"

int main(int argc, char** argv) {
  using namespace stiffsim;
  if (argc != 2) {
    std::fprintf(stderr, "usage: free_fall <models dir>\n");
    return 2;
  }
  constexpr double kG = 9.81, kT = 1.0;
  try {
    const SceneConfig config =
        load_scene(std::string(argv[1]) + "/free_body.yaml", {"gravity=[0, 0, -9.81]"});
    RunOverrides overrides;
    overrides.integrator = "rk45";
    overrides.accuracy = 1e-10;
    const RunSettings settings = run_settings(config, overrides);
    const Scene& scene = *config.scene;
    auto integrator =
        make_integrator(settings.integrator_name, scene, settings.integrator, settings.implicit);
    const State initial = scene.initial_state();
    integrator->initialize(initial);
    integrator->integrate_to(kT);

    const State& end = integrator->state();
    const Dimensions d = scene.dimensions();
    // Positions x, y, z, quaternion; velocities vx, vy, vz, angular (names in
    // free_body.yaml's order, checked so that a new layout fails loudly).
    if (scene.position_names()[2] != "box/floating_base/z" ||
        scene.velocity_names()[2] != "box/floating_base/vz") {
      std::fprintf(stderr, "unexpected state layout: %s, %s\n", scene.position_names()[2].c_str(),
                   scene.velocity_names()[2].c_str());
      return 1;
    }
    const double z = end.q(d)[2], vz = end.v(d)[2];
    // The evaluations' workspace (system.h), as a caller that loops keeps it.
    const std::unique_ptr<SystemData> data = scene.make_data();
    const double energy_start = scene.energy(*data, initial);
    const double energy_drift = std::abs(scene.energy(*data, end) - energy_start) / energy_start;
    std::printf("t %.3f  z %.12f (exact %.12f)  vz %.12f (exact %.12f)  energy drift %.1e\n", end.t,
                z, -0.5 * kG * kT * kT, vz, -kG * kT, energy_drift);
    const bool ok = end.t == kT && std::abs(z + 0.5 * kG * kT * kT) < 1e-9 &&
                    std::abs(vz + kG * kT) < 1e-9 && energy_drift < 1e-9 &&
                    integrator->statistics().steps_taken > 0;
    std::printf("%s\n", ok ? "free fall: ok" : "free fall: FAILED");
    return ok ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "free_fall: %s\n", e.what());
    return 1;
  }
}
