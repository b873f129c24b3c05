// The scene key root_motion on URDF components: the shipped shaken chain
// loads and its base follows the sinusoid, its drawing is the still
// chain's carried along the path, and bad uses are refused with the line
// that holds them.

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/io/scene_drawing.h"
#include "stiffsim/io/scene_yaml.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/rigid_tree.h"

namespace stiffsim {
namespace {

std::string model_path(const std::string& name) {
  return std::string(STIFFSIM_SOURCE_DIR) + "/models/" + name;
}

TEST(SceneYamlRootMotion, TheShakenChainsBaseFollowsItsSinusoid) {
  const SceneConfig config = load_scene(model_path("chain10_shake.yaml"));
  const auto* chain = dynamic_cast<const ArticulatedSystem*>(&config.scene->component(0));
  ASSERT_NE(chain, nullptr);
  for (double t : {0.0, 0.1, 0.37}) {
    EXPECT_NEAR(chain->root_displacement(t).x(), 0.05 * std::sin(4.0 * M_PI * t), 1e-15);
    EXPECT_NEAR(chain->root_velocity(t).x(), 0.05 * 4.0 * M_PI * std::cos(4.0 * M_PI * t), 1e-13);
    EXPECT_EQ(chain->root_displacement(t).tail<2>(), Eigen::Vector2d::Zero());
  }
}

TEST(SceneYamlRootMotion, TheDrawingIsTheStillChainCarriedAlongThePath) {
  // Same state, base shaken or still: every point (world anchor included)
  // moves by d(t) and gains d'(t); the segments are the same.
  auto scene = [](std::optional<std::array<ScalarPath, 3>> motion) {
    ArticulatedOptions o;
    o.root_motion = std::move(motion);
    std::vector<std::unique_ptr<System>> parts;
    parts.push_back(std::make_unique<ArticulatedSystem>(make_chain_tree(3, "chain"), o));
    return std::make_unique<Scene>("chain", std::move(parts));
  };
  const double A = 0.05, f = 2.0, w = 2.0 * M_PI * f;
  const auto shaken =
      scene(std::array<ScalarPath, 3>{ScalarPath::sinusoid(0.0, A, f, 0.0, "x"),
                                      ScalarPath::constant(0.1), ScalarPath::constant(0.0)});
  const auto still = scene(std::nullopt);
  Eigen::VectorXd x(6);
  x << 0.3, -0.2, 0.5, 1.0, -0.7, 0.4;
  const double t = 0.1;
  const Eigen::Vector3d d(A * std::sin(w * t), 0.1, 0.0), d_dot(A * w * std::cos(w * t), 0.0, 0.0);
  const ComponentDrawing a = draw_scene(*shaken, {}, t, x).at(0);
  const ComponentDrawing b = draw_scene(*still, {}, t, x).at(0);
  ASSERT_EQ(a.points.cols(), b.points.cols());
  EXPECT_EQ(a.segments, b.segments);
  EXPECT_EQ(a.fixed, b.fixed);
  EXPECT_LT((a.points - (b.points.colwise() + d)).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LT((a.velocities - (b.velocities.colwise() + d_dot)).cwiseAbs().maxCoeff(), 1e-14);
}

std::string error(const std::string& motion, const std::string& formulation = "exact",
                  const std::string& extra = "") {
  try {
    parse_scene("components:\n  - name: c\n    type: urdf\n    file: chain_2.urdf\n" + extra +
                    "    formulation: " + formulation + "\n    root_motion:\n" + motion,
                model_path("bad.yaml"));
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(SceneYamlRootMotion, ErrorsNameTheLine) {
  const std::string keyed = error("      x: 0\n      z: {keyframes: [[0, 0], [1, 0.2]]}\n");
  EXPECT_NE(keyed.find("bad.yaml:8:"), std::string::npos) << keyed;
  EXPECT_NE(keyed.find("root_motion.z is keyframed"), std::string::npos) << keyed;
  const std::string axis = error("      w: 0.1\n");
  EXPECT_NE(axis.find("bad.yaml:7:"), std::string::npos) << axis;
  EXPECT_NE(axis.find("unknown key 'root_motion.w' (expected one of: x, y, z)"), std::string::npos)
      << axis;
  const std::string compliant = error("      x: 0.1\n", "compliant");
  EXPECT_NE(compliant.find("bad.yaml:7:"), std::string::npos) << compliant;
  EXPECT_NE(compliant.find("root_motion needs formulation: exact"), std::string::npos) << compliant;
  const std::string floating = error("      x: 0.1\n", "exact", "    floating_base: true\n");
  EXPECT_NE(floating.find("joined to the world by a floating joint"), std::string::npos)
      << floating;
}

}  // namespace
}  // namespace stiffsim
