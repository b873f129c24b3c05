// Stiff and extreme cases, each run by VIE, IE, the explicit methods and,
// for chains, MuJoCo, with one pass criterion: no NaN, the energy of these
// passive scenes never above its initial value (plus a stated tolerance),
// and the run either finishes or fails with a clear message.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <sstream>

#include "stiffsim/error.h"
#include "stiffsim/integrators/simulator.h"
#include "stiffsim/io/atomic_file.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/peers/mujoco_peer.h"
#include "stiffsim/reports/method_run.h"
#include "stiffsim/reports/reports.h"

namespace stiffsim {
namespace {

// Energy may rise by this fraction of its scale: implicit Euler with a
// configuration-dependent M trades O(h^2) energy per step (README), and
// Newton stops at its tolerance.
constexpr double kEnergyTolerance = 1e-3;

struct Case {
  std::string name;
  std::function<BenchScene()> build;
  double h;
  std::vector<std::string> methods;
  int mujoco_links = 0;        // > 0: also MuJoCo on chain_N.urdf
  double joint_stiffness = 0;  // for MuJoCo
  double angle = 0.0;
  double rest = 0.0, damping = 0.0;  // for MuJoCo
};

struct Outcome {
  std::string case_name, method, verdict;
  double energy_ratio = std::numeric_limits<double>::quiet_NaN();
  long steps = 0, newton_failures = 0;
  double wall = 0.0;
  std::string message;
  bool pass = false;
};

// The 20-node rope the particle cases start from.
ParticleDescription small_rope() {
  RopeSpec spec;
  spec.nodes = 20;
  spec.total_mass = 0.1;
  spec.stretch = SpringParameters{1e4, 0.01};
  return make_rope(spec);
}

BenchScene mass_ratio_rope(double ratio, double t_final) {
  ParticleDescription d = small_rope();
  for (std::size_t i = 0; i < d.masses.size(); ++i) d.masses[i] = i % 2 ? 0.01 : 0.01 / ratio;
  return wrap_scene("rope, neighbour mass ratio " + format_number("%.0e", ratio), "rope",
                    std::make_unique<ParticleSystem>(d), t_final, 1e-2);
}

BenchScene stretched_rope(double stretch, double t_final) {
  ParticleDescription d = small_rope();
  for (Spring& s : d.springs) s.rest_length /= stretch;
  return wrap_scene("rope stretched " + format_number("%.0f", stretch) + "x", "rope", std::make_unique<ParticleSystem>(d),
                    t_final, 1e-2);
}

BenchScene collapsed_rope(double t_final) {
  ParticleDescription d = small_rope();
  for (auto& p : d.positions) p = d.positions[0];  // every spring at zero length, rest lengths kept
  return wrap_scene("rope collapsed to a point", "rope", std::make_unique<ParticleSystem>(d), t_final, 1e-2);
}

BenchScene spinning_body(double omega, double t_final) {
  RigidTree t;
  t.name = "box";
  TreeBody b;
  b.link = b.joint = "box";
  b.type = JointType::kFloating;
  b.inertia.mass = 1.0;
  b.inertia.inertia = Eigen::Vector3d(0.016667, 0.014167, 0.0041667).asDiagonal();
  t.bodies.push_back(b);
  ArticulatedOptions o;
  o.gravity.setZero();
  o.initial_v = Eigen::VectorXd::Zero(6);
  o.initial_v.tail<3>() << 0.01 * omega, omega, 0.01 * omega;
  return wrap_scene("free body at " + format_number("%.0f", omega) + " rad/s", "free-body",
                    std::make_unique<ArticulatedSystem>(t, o), t_final, 1e-3);
}

Outcome judge(const std::string& case_name, const BenchScene& s, const MethodRun& run) {
  Outcome o;
  o.case_name = case_name;
  o.method = run.spec.method;
  o.steps = run.steps;
  o.newton_failures = run.newton_failures;
  o.wall = run.wall_seconds;
  o.message = run.message;
  // The energy's own scale, whatever the zero of the potential: |E0| or the
  // most kinetic energy the motion reached.
  const double scale = std::max({std::abs(run.energy_start), run.kinetic_max, 1e-12});
  if (run.energy_max == run.energy_max) o.energy_ratio = (run.energy_max - run.energy_start) / scale;
  const bool energy_ok = !(o.energy_ratio > kEnergyTolerance);
  if (run.non_finite) {
    o.verdict = "FAIL: NaN";
  } else if (!energy_ok) {
    o.verdict = "FAIL: energy grew";
  } else if (run.finished) {
    o.verdict = "stable";
    o.pass = true;
  } else if (run.over_budget) {
    o.verdict = "over budget";
    o.pass = true;  // nothing wrong was produced; the table says it did not finish
  } else {
    o.verdict = "stopped with a clear message";
    o.pass = !o.message.empty();
  }
  (void)s;
  return o;
}

}  // namespace

int run_stability_report(const ReportOptions& options) {
  namespace fs = std::filesystem;
  create_report_directory(options.out_dir);
  auto say = [&](const std::string& line) {
    if (options.log) *options.log << line << std::endl;
  };
  const bool quick = options.quick;
  const double T = quick ? 0.5 : 2.0;
  const int n = quick ? 8 : 16;
  const std::vector<std::string> all = {"vie", "ie", "semi-explicit-euler", "rk45"};
  std::vector<Case> cases;
  for (double k : quick ? std::vector<double>{1e2, 1e4, 1e6, 1e9}
                        : std::vector<double>{1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9}) {
    cases.push_back({"cloth " + std::to_string(n) + "x" + std::to_string(n) + ", stretch k " + format_number("%.0e", k) +
                         ", h 1/60",
                     [=] { return cloth_scene(n, k, T); }, 1.0 / 60.0, all});
  }
  for (double h : {1e-4, 1e-3, 1e-2, 1e-1}) {
    cases.push_back({"cloth k 1e4, h " + format_number("%.0e", h), [=] { return cloth_scene(n, 1e4, T); }, h, all});
  }
  cases.push_back({"rope, neighbour mass ratio 1e6, h 1e-2", [=] { return mass_ratio_rope(1e6, T); }, 1e-2, all});
  cases.push_back({"rope stretched 10x, h 1e-2", [=] { return stretched_rope(10.0, T); }, 1e-2, all});
  cases.push_back({"rope collapsed (zero-length springs), h 1e-2", [=] { return collapsed_rope(T); }, 1e-2, all});
  for (double k : {1e4, 1e8}) {
    Case c{"chain 10, joint stiffness " + format_number("%.0e", k) + ", h 1e-2",
           [=] { return chain_scene(10, 0.3, k, T); }, 1e-2, all};
    c.mujoco_links = 10;
    c.joint_stiffness = k;
    c.angle = 0.3;
    cases.push_back(c);
  }
  // Stiff position drives (a user's report: MuJoCo's position servos, explicit
  // in their stiffness, diverge on a humanoid at kp = 1e5 and h = 5 ms). A
  // drive holding a constant target is a joint spring about it; MuJoCo gets
  // that spring (explicit in its `implicit` integrator) and the drive's kd as
  // joint damping (implicit there).
  for (double kp : quick ? std::vector<double>{1e2, 1e5, 1e8}
                         : std::vector<double>{1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9}) {
    const double kd = 1.0;
    Case c{"chain 10 driven to 0.2 rad, kp " + format_number("%.0e", kp) + ", kd 1, h 5e-3",
           [=] { return driven_chain_scene(10, 0.2, kp, kd, T); }, 5e-3, all};
    c.mujoco_links = 10;
    c.joint_stiffness = kp;
    c.angle = c.rest = 0.2;
    c.damping = kd;
    cases.push_back(c);
  }
  cases.push_back({"free body spinning at 1000 rad/s, h 1e-3", [=] { return spinning_body(1000.0, quick ? 0.1 : 1.0); },
                   1e-3, all});
  const int links = quick ? 200 : 1000;
  cases.push_back({"compliant chain " + std::to_string(links) + ", h 1e-2",
                   [=] { return compliant_chain_scene(links, 0.05, 1e6, 1e4, quick ? 0.2 : 1.0); }, 1e-2,
                   {"vie", "ie", "semi-explicit-euler"}});

  std::vector<Outcome> outcomes;
  for (const Case& c : cases) {
    const BenchScene s = c.build();
    for (const std::string& m : c.methods) {
      BenchRunOptions o;
      o.track_energy = true;
      o.wall_budget_seconds = quick ? 10.0 : 60.0;
      BenchScene scene = c.build();
      scene.sample_period = scene.t_final;
      const MethodRun run = run_stiffsim(scene, {m, true, c.h}, o);
      outcomes.push_back(judge(c.name, scene, run));
      say("stability: " + c.name + ", " + m + ": " + outcomes.back().verdict);
    }
    if (c.mujoco_links > 0 && mujoco_available()) {
      for (const char* integrator : {"implicit", "RK4"}) {
        MujocoProblem p;
        p.urdf_path = options.models_dir + "/chain_" + std::to_string(c.mujoco_links) + ".urdf";
        for (int i = 0; i < c.mujoco_links; ++i) p.joints.push_back("joint_" + std::to_string(i + 1));
        p.initial_q.assign(c.mujoco_links, c.angle);
        p.initial_v.assign(c.mujoco_links, 0.0);
        p.stiffness.assign(c.mujoco_links, c.joint_stiffness);
        p.rest.assign(c.mujoco_links, c.rest);
        p.damping.assign(c.mujoco_links, c.damping);
        p.integrator = integrator;
        p.step = c.h;
        p.t_final = s.t_final;
        p.sample_times = sample_times(0.0, s.t_final, c.h);
        Outcome o;
        o.case_name = c.name;
        o.method = std::string("mujoco-") + (std::string(integrator) == "RK4" ? "rk4" : "implicit");
        try {
          const PeerRun r = run_mujoco(p);
          o.steps = r.steps;
          o.wall = r.wall_seconds;
          o.message = r.message;
          // Energy of MuJoCo's states in stiffsim's model of the same chain.
          const std::unique_ptr<SystemData> data = s.scene->make_data();
          const double e0 = s.scene->energy(*data, s.scene->initial_state());
          double emax = e0;
          bool finite = true;
          for (const Eigen::VectorXd& x : r.samples) {
            finite &= x.allFinite();
            if (!x.allFinite()) break;
            emax = std::max(emax, s.scene->energy(*data, State(0.0, x)));
          }
          o.energy_ratio = (emax - e0) / std::max(std::abs(e0), 1e-12);  // e0 != 0: the chain starts raised
          if (!finite) {
            o.verdict = "FAIL: NaN";
          } else if (o.energy_ratio > kEnergyTolerance) {
            o.verdict = "FAIL: energy grew";
          } else if (r.failed) {
            o.verdict = "stopped with a clear message";
            o.pass = true;
          } else {
            o.verdict = "stable";
            o.pass = true;
          }
        } catch (const std::exception& e) {
          o.verdict = "not run";
          o.message = e.what();
        }
        outcomes.push_back(o);
        say("stability: " + c.name + ", " + o.method + ": " + o.verdict);
      }
    }
  }

  std::ostringstream csv;
  csv << "case,method,verdict,pass,max_energy_gain_relative,steps,newton_failures,wall_seconds,message\n";
  std::ostringstream md;
  md << "# Stability\n\nMachine: " << machine_description() << ".\n\n"
     << "Every case at a fixed step. Pass: no NaN, energy never above its initial value by more than "
     << kEnergyTolerance << " of its scale, max(|E0|, the largest kinetic energy reached) (these "
     << "scenes are passive: no work is done on them), and the run "
     << "finishes or stops with a clear message (explicit methods stop when a step blows up). "
     << "Energy gain: (max E - E0) / that scale; for MuJoCo (|E0| scale), its states' energy in stiffsim's model of the "
     << "same chain at every step.\n\n"
     << "| case | method | verdict | max energy gain | steps | Newton failures | wall s |\n|---|---|---|---|---|---|---|\n";
  int passed = 0;
  for (const Outcome& o : outcomes) {
    passed += o.pass;
    csv << csv_field(o.case_name) << "," << o.method << "," << csv_field(o.verdict) << "," << (o.pass ? 1 : 0) << ","
        << format_number("%.3e", o.energy_ratio) << "," << o.steps << "," << o.newton_failures << ","
        << format_number("%.4f", o.wall) << "," << csv_field(o.message) << "\n";
    md << "| " << o.case_name << " | " << o.method << " | " << (o.pass ? "" : "**") << o.verdict
       << (o.pass ? "" : "**") << " | " << format_number("%.1e", o.energy_ratio) << " | " << o.steps << " | "
       << o.newton_failures << " | " << format_number("%.3f", o.wall) << " |\n";
  }
  md << "\n" << passed << " of " << outcomes.size() << " runs pass.\n";
  // Each file appears whole or not at all, and a failed write is an error.
  write_file_atomically((fs::path(options.out_dir) / "stability.csv").string(), csv.str());
  write_file_atomically((fs::path(options.out_dir) / "stability.md").string(), md.str());
  say("stability: wrote " + (fs::path(options.out_dir) / "stability.csv").string() + " and stability.md");
  return 0;
}

}  // namespace stiffsim
