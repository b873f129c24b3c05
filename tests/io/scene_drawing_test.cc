// The drawing of a scene: points where the state and the pins' paths put
// them, and segments that join what the model joins.

#include "stiffsim/io/scene_drawing.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/io/scene_yaml.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/compliant.h"
#include "stiffsim/model/particles.h"
#include "stiffsim/model/rigid_tree.h"

namespace stiffsim {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::string model_path(const std::string& name) {
  return std::string(STIFFSIM_SOURCE_DIR) + "/models/" + name;
}

const ParticleSystem& particles(const SceneConfig& config) {
  const auto* p = dynamic_cast<const ParticleSystem*>(&config.scene->component(0));
  EXPECT_NE(p, nullptr);
  return *p;
}

TEST(SceneDrawing, RopePointsAreItsStateAndItsMovingPin) {
  // The shaken rope: node 0 pinned and moving along z (sinusoid) and y
  // (keyframes), the other nodes free.
  const SceneConfig config = load_scene(model_path("rope_shake.yaml"), {"rope.nodes=6"});
  const ParticleSystem& rope = particles(config);
  const Dimensions dims = config.scene->dimensions();
  Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(dims.nx(), -1.0, 2.0);
  const double t = 0.3;
  const std::vector<ComponentDrawing> drawing = draw_scene(*config.scene, config.surfaces, t, x);
  ASSERT_EQ(drawing.size(), 1u);
  const ComponentDrawing& d = drawing[0];
  EXPECT_EQ(d.name, "rope");
  ASSERT_EQ(d.points.cols(), 6);
  for (int n = 1; n < 6; ++n) {
    EXPECT_EQ(Eigen::Vector3d(d.points.col(n)), Eigen::Vector3d(x.segment<3>(3 * (n - 1)))) << n;
  }
  // The pin's path in closed form: y by the keyframes (0, 0) -> (1, 0.1),
  // z = 0.15 sin(2 pi 1.5 t), both about the rest position.
  const Eigen::Vector3d rest = rope.description().positions[0];
  const Eigen::Vector3d pin =
      rest + Eigen::Vector3d(0.0, 0.1 * t, 0.15 * std::sin(2.0 * kPi * 1.5 * t));
  EXPECT_LT((Eigen::Vector3d(d.points.col(0)) - pin).norm(), 1e-15);
  EXPECT_EQ(d.fixed, std::vector<int>{0});
  // The stretch springs, not the bend springs (two nodes apart).
  const std::vector<std::array<int, 2>> chain{{0, 1}, {1, 2}, {2, 3}, {3, 4}, {4, 5}};
  EXPECT_EQ(d.segments, chain);
}

TEST(SceneDrawing, ClothSegmentsAreTheEdgesOfItsTriangles) {
  const int nx = 5, ny = 3;
  const SceneConfig config = load_scene(model_path("cloth.yaml"), {"cloth.nodes=[5, 3]"});
  const ParticleSystem& cloth = particles(config);
  const State s = config.scene->initial_state();
  const std::vector<ComponentDrawing> drawing =
      draw_scene(*config.scene, config.surfaces, 0.0, s.x);
  ASSERT_EQ(drawing.size(), 1u);
  const ComponentDrawing& d = drawing[0];
  ASSERT_EQ(d.points.cols(), nx * ny);
  for (int n = 0; n < nx * ny; ++n) {
    EXPECT_EQ(Eigen::Vector3d(d.points.col(n)), cloth.description().positions[n]) << n;
  }
  EXPECT_EQ(d.fixed, cloth.description().pinned);
  // Every grid cell is split into two triangles by one diagonal: the rows'
  // and columns' edges plus one diagonal per cell.
  ASSERT_EQ(config.surfaces[0].size(), 2u * (nx - 1) * (ny - 1));
  EXPECT_EQ(d.segments.size(),
            static_cast<size_t>(nx * (ny - 1) + ny * (nx - 1) + (nx - 1) * (ny - 1)));
  for (const auto& seg : d.segments) {
    EXPECT_LT(seg[0], seg[1]);
    EXPECT_LT(seg[1], nx * ny);
  }
}

TEST(SceneDrawing, ClothWithoutItsSurfaceIsDrawnAsItsConsecutiveSprings) {
  const SceneConfig config = load_scene(model_path("cloth.yaml"), {"cloth.nodes=[4, 4]"});
  const State s = config.scene->initial_state();
  // Triangles in another numbering are ignored, as the VTK writer does.
  const std::vector<ComponentDrawing> drawing = draw_scene(*config.scene, {{{0, 1, 99}}}, 0.0, s.x);
  ASSERT_EQ(drawing.size(), 1u);
  for (const auto& seg : drawing[0].segments) EXPECT_EQ(seg[1] - seg[0], 1);
  EXPECT_FALSE(drawing[0].segments.empty());
}

// chain_2 (0.1 m links hanging along -z, revolute about y) at joint angles
// a, b: R_y(a) (0, 0, -L) = (-L sin a, 0, -L cos a).
void expect_chain_2(const ComponentDrawing& d, double a, double b) {
  const double L = 0.1;
  ASSERT_EQ(d.points.cols(), 4);  // two bodies, the world anchor, the tip
  const Eigen::Vector3d body1(-L * std::sin(a), 0.0, -L * std::cos(a));
  const Eigen::Vector3d tip =
      body1 + Eigen::Vector3d(-L * std::sin(a + b), 0.0, -L * std::cos(a + b));
  EXPECT_LT(Eigen::Vector3d(d.points.col(0)).norm(), 1e-12);
  EXPECT_LT((Eigen::Vector3d(d.points.col(1)) - body1).norm(), 1e-12);
  EXPECT_LT(Eigen::Vector3d(d.points.col(2)).norm(), 1e-12);
  EXPECT_LT((Eigen::Vector3d(d.points.col(3)) - tip).norm(), 1e-12);
  const std::vector<std::array<int, 2>> segments{{2, 0}, {0, 1}, {1, 3}};
  EXPECT_EQ(d.segments, segments);
  EXPECT_EQ(d.fixed, std::vector<int>{2});
}

std::unique_ptr<Scene> one_component_scene(std::unique_ptr<System> system) {
  std::vector<std::unique_ptr<System>> components;
  components.push_back(std::move(system));
  return std::make_unique<Scene>("chain_2", std::move(components));
}

TEST(SceneDrawing, ExactChainBodiesSitAtClosedFormPositions) {
  const double a = 0.4, b = -1.1;
  auto scene = one_component_scene(
      std::make_unique<ArticulatedSystem>(make_chain_tree(2, "chain"), ArticulatedOptions{}));
  Eigen::VectorXd x = Eigen::VectorXd::Zero(scene->dimensions().nx());
  x[0] = a;
  x[1] = b;
  const std::vector<ComponentDrawing> drawing = draw_scene(*scene, {}, 0.0, x);
  ASSERT_EQ(drawing.size(), 1u);
  EXPECT_EQ(drawing[0].name, "chain");
  expect_chain_2(drawing[0], a, b);
}

TEST(SceneDrawing, CompliantChainIsDrawnLikeTheExactOne) {
  // The compliant formulation's q are the free bodies' world poses; its
  // bushings stand for the joints, so the picture is the exact chain's.
  const double a = 0.4, b = -1.1;
  ArticulatedOptions exact;
  exact.initial_q = Eigen::Vector2d(a, b);
  exact.initial_v = Eigen::Vector2d::Zero();
  auto scene =
      one_component_scene(make_compliant(make_chain_tree(2, "chain"), exact, BushingParameters{}));
  const State s = scene->initial_state();
  const std::vector<ComponentDrawing> drawing = draw_scene(*scene, {}, 0.0, s.x);
  ASSERT_EQ(drawing.size(), 1u);
  expect_chain_2(drawing[0], a, b);
}

TEST(SceneDrawing, BodyReachesOutToItsAttachmentPoint) {
  // models/box_on_rope.yaml: the free box is one body whose centre of mass
  // is its origin, so without its hook it would be a lone point. Its
  // drawing is the origin and the hooked corner joined by a segment, the
  // corner where the rope's first node starts, moving as the rigid body
  // moves it.
  const SceneConfig config = load_scene(model_path("box_on_rope.yaml"));
  const Scene& scene = *config.scene;
  Eigen::VectorXd x = scene.initial_state().x;
  const Dimensions d = scene.dimensions();
  // Turn the box a quarter turn about z and spin it about x.
  x.segment<4>(3) = Eigen::Vector4d(std::sqrt(0.5), 0.0, 0.0, std::sqrt(0.5));
  x[d.nq + 3] = 2.0;
  const auto drawing = draw_scene(scene, config.surfaces, 0.0, x);
  ASSERT_EQ(drawing.size(), 2u);
  const ComponentDrawing& box = drawing[0];
  ASSERT_EQ(box.points.cols(), 2);
  ASSERT_EQ(box.segments.size(), 1u);
  EXPECT_EQ(box.segments[0], (std::array<int, 2>{0, 1}));
  // (0.05, 0.1, -0.2) turned a quarter about z: (-0.1, 0.05, -0.2).
  EXPECT_LT((box.points.col(1) - Eigen::Vector3d(-0.1, 0.05, -0.2)).norm(), 1e-12);
  // omega = 2 about the body's x, which the turn sent to the world's y:
  // (0, 2, 0) x (-0.1, 0.05, -0.2) = (-0.4, 0, 0.2).
  EXPECT_LT((box.velocities.col(1) - Eigen::Vector3d(-0.4, 0.0, 0.2)).norm(), 1e-12);
  // Unturned, the corner is where the rope starts.
  const auto still = draw_scene(scene, config.surfaces, 0.0, scene.initial_state().x);
  EXPECT_LT((still[0].points.col(1) - still[1].points.col(0)).norm(), 1e-12);
}

TEST(SceneDrawing, StateOfTheWrongSizeIsRejected) {
  const SceneConfig config = load_scene(model_path("rope.yaml"), {"rope.nodes=4"});
  EXPECT_THROW(draw_scene(*config.scene, config.surfaces, 0.0, Eigen::VectorXd::Zero(5)),
               InputError);
}

}  // namespace
}  // namespace stiffsim
