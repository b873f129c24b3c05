#include "stiffsim/reports/bench_scenes.h"

#include <cmath>
#include <vector>

namespace stiffsim {

namespace {
std::unique_ptr<Scene> single(const std::string& name, std::unique_ptr<System> system) {
  std::vector<std::unique_ptr<System>> components;
  components.push_back(std::move(system));
  return std::make_unique<Scene>(name, std::move(components));
}
}  // namespace

BenchScene cloth_scene(int nx, double stretch_k, double t_final, double size, double total_mass) {
  ClothSpec spec;
  spec.nx = spec.ny = nx;
  spec.width = spec.height = size;
  spec.total_mass = total_mass;
  spec.stretch = SpringParameters{stretch_k, 0.5};
  spec.shear = SpringParameters{100.0, 0.1};
  spec.bend = SpringParameters{10.0, 0.05};
  BenchScene s;
  s.kind = stretch_k >= 1e5 ? "stiff-cloth" : "cloth";
  s.name = s.kind + " " + std::to_string(nx) + "x" + std::to_string(nx);
  s.scene = single(s.name, std::make_unique<ParticleSystem>(make_cloth(spec)));
  s.t_final = t_final;
  s.step = 1.0 / 60.0;
  return s;
}

BenchScene rope_scene(int nodes, double stretch_k, double t_final, double length, double total_mass) {
  RopeSpec spec;
  spec.nodes = nodes;
  spec.length = length;
  spec.total_mass = total_mass;
  spec.stretch = SpringParameters{stretch_k, 0.1};
  spec.bend = SpringParameters{1.0, 0.01};
  BenchScene s;
  s.kind = "rope";
  s.name = "rope " + std::to_string(nodes);
  s.scene = single(s.name, std::make_unique<ParticleSystem>(make_rope(spec)));
  s.t_final = t_final;
  s.step = 1e-3;
  return s;
}

BenchScene cloth_scene_at_shipped_spacing(int nx, double stretch_k, double t_final) {
  return cloth_scene(nx, stretch_k, t_final, (nx - 1) / 31.0, 0.4 * nx * nx / 1024.0);
}

BenchScene rope_scene_at_shipped_spacing(int nodes, double stretch_k, double t_final) {
  return rope_scene(nodes, stretch_k, t_final, (nodes - 1) / 49.0, 0.1 * nodes / 50.0);
}

BenchScene chain_scene(int links, double angle, double joint_stiffness, double t_final) {
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::Constant(links, angle);
  o.joint_forces.assign(links, JointForce{joint_stiffness, 0.0, 0.0});
  BenchScene s;
  s.kind = "chain";
  s.name = "chain " + std::to_string(links);
  s.scene = single(s.name, std::make_unique<ArticulatedSystem>(make_chain_tree(links), o));
  s.t_final = t_final;
  s.step = 1e-3;
  return s;
}

BenchScene driven_chain_scene(int links, double target, double kp, double kd, double t_final) {
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::Constant(links, target);
  for (int i = 0; i < links; ++i) o.drives.push_back(JointDrive{i, kp, kd, ScalarPath::constant(target)});
  BenchScene s;
  s.kind = "driven-chain";
  s.name = "driven chain " + std::to_string(links);
  s.scene = single(s.name, std::make_unique<ArticulatedSystem>(make_chain_tree(links), o));
  s.t_final = t_final;
  s.step = 5e-3;
  return s;
}

BenchScene compliant_chain_scene(int links, double angle, double k_lin, double k_ang, double t_final) {
  ArticulatedOptions o;
  o.initial_q = Eigen::VectorXd::Constant(links, angle);
  // About 1% of critical damping of one link on each spring.
  const BushingParameters b{k_lin, 0.02 * std::sqrt(k_lin * 0.1), k_ang,
                            0.02 * std::sqrt(k_ang * 0.1 * 0.01 / 3.0)};
  BenchScene s;
  s.kind = "compliant-chain";
  s.name = "compliant chain " + std::to_string(links);
  s.scene = single(s.name, make_compliant(make_chain_tree(links), o, b));
  s.t_final = t_final;
  s.step = 1e-3;
  return s;
}

BenchScene wrap_scene(std::string name, std::string kind, std::unique_ptr<System> system, double t_final,
                      double step) {
  BenchScene s;
  s.name = std::move(name);
  s.kind = std::move(kind);
  s.scene = single(s.name, std::move(system));
  s.t_final = t_final;
  s.step = step;
  return s;
}

}  // namespace stiffsim
