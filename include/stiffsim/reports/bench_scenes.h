#pragma once
// The scenes of the reports, built in code at any size (MODELS.md shapes):
// cloth grids, particle ropes, and the chain of chain_N.urdf in either
// formulation, so that scaling studies need no generated files.

#include <memory>
#include <string>

#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/scene.h"

namespace stiffsim {

struct BenchScene {
  std::string name;         // as reports name it, e.g. "cloth 20x20"
  std::string kind;         // cloth | stiff-cloth | rope | chain | compliant-chain | free-body | ...
  std::unique_ptr<Scene> scene;
  double t_final = 1.0;
  double sample_period = 0.05;
  double step = 0.01;         // the natural fixed step (or maximum step)
  bool passive = true;        // no work done on it: energy may never rise
  int dofs() const { return scene->dimensions().nv; }
};

// nx x nx cloth with the springs of models/cloth.yaml and the given stretch
// k, `size` metres square and `total_mass` kg.
BenchScene cloth_scene(int nx, double stretch_k, double t_final, double size = 1.0, double total_mass = 0.4);
// A particle rope of `nodes` nodes, stretch k, pinned at node 0.
BenchScene rope_scene(int nodes, double stretch_k, double t_final, double length = 1.0,
                      double total_mass = 0.1);
// The same at the node spacing and node mass of the shipped scenes
// (models/cloth.yaml: 32 x 32 nodes on 1 m, 0.4 kg; models/rope.yaml: 50
// nodes on 1 m, 0.1 kg) whatever the size: a larger sheet, a longer rope,
// whose nodes' dynamics do not change with n.
BenchScene cloth_scene_at_shipped_spacing(int nx, double stretch_k, double t_final);
BenchScene rope_scene_at_shipped_spacing(int nodes, double stretch_k, double t_final);
// The chain in reduced coordinates, every joint at `angle`, optional spring.
BenchScene chain_scene(int links, double angle, double joint_stiffness, double t_final);
// The chain as free bodies and bushings (k_lin, k_ang as given, damped at
// about 1% of critical on a link).
// chain_N with a PD drive on every joint holding `target`, started there.
BenchScene driven_chain_scene(int links, double target, double kp, double kd, double t_final);
BenchScene compliant_chain_scene(int links, double angle, double k_lin, double k_ang, double t_final);

// Only the scene of a System built elsewhere (stability cases).
BenchScene wrap_scene(std::string name, std::string kind, std::unique_ptr<System> system, double t_final,
                      double step);

}  // namespace stiffsim
