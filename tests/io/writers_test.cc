// The trajectory CSV, stats JSON and VTK writers: formats, and the promise
// that no file appears under its final name before it is complete.

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "stiffsim/error.h"
#include "stiffsim/io/stats_writer.h"
#include "stiffsim/io/trajectory_writer.h"
#include "stiffsim/io/vtk_writer.h"
#include "stiffsim/model/articulated.h"
#include "stiffsim/model/particle_meshes.h"
#include "stiffsim/model/particles.h"
#include "stiffsim/scene.h"

namespace stiffsim {
namespace {

namespace fs = std::filesystem;

class TempDir {
 public:
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = fs::temp_directory_path() /
            ("stiffsim_writers_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() { fs::remove_all(path_); }
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  std::vector<std::string> entries() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(path_)) names.push_back(e.path().filename());
    std::sort(names.begin(), names.end());
    return names;
  }

 private:
  fs::path path_;
};

std::string read(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

std::vector<std::string> lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

// A 3-node rope pinned at node 0 (two free nodes, 6 DOFs) and a 2x2 cloth
// pinned at two corners (two free nodes): small enough to check by hand.
std::unique_ptr<Scene> small_scene() {
  RopeSpec rope;
  rope.name = "rope";
  rope.nodes = 3;
  rope.stretch = SpringParameters{10.0, 0.1};
  ClothSpec cloth;
  cloth.name = "cloth";
  cloth.stretch = SpringParameters{10.0, 0.1};
  std::vector<std::unique_ptr<System>> components;
  components.push_back(std::make_unique<ParticleSystem>(make_rope(rope)));
  components.push_back(std::make_unique<ParticleSystem>(make_cloth(cloth)));
  return std::make_unique<Scene>("small", std::move(components));
}

TEST(AppendNumber, ShortestRoundTrip) {
  const std::vector<double> values = {0.1,           1.0 / 3.0, -2.5e-300,
                                      6.02214076e23, 0.0,       std::nextafter(1.0, 2.0)};
  for (double v : values) {
    std::string text;
    append_number(v, &text);
    EXPECT_EQ(std::stod(text), v) << text;
  }
  std::string text;
  append_number(0.1, &text);
  EXPECT_EQ(text, "0.1");  // not 0.10000000000000001
}

TEST(TrajectoryWriter, HeaderRowsAndAtomicRename) {
  TempDir dir;
  const auto scene = small_scene();
  const std::string path = dir.file("t.csv");
  {
    TrajectoryWriter writer(path, *scene);
    EXPECT_FALSE(fs::exists(path)) << "visible before finish()";
    EXPECT_TRUE(fs::exists(path + ".tmp"));
    Eigen::VectorXd x(24);
    for (int i = 0; i < 24; ++i) x[i] = i / 10.0;
    writer.write(0.0, x);
    writer.write(0.25, x * 2.0);
    EXPECT_EQ(writer.rows(), 2);
    writer.finish();
  }
  EXPECT_FALSE(fs::exists(path + ".tmp"));
  const std::vector<std::string> rows = lines(read(path));
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0].rfind("t,q:rope/n1/x,q:rope/n1/y,q:rope/n1/z,q:rope/n2/x,", 0), 0u) << rows[0];
  EXPECT_NE(rows[0].find(",v:rope/n1/x,"), std::string::npos);
  EXPECT_NE(rows[0].find(",q:cloth/n0/x,"), std::string::npos);
  EXPECT_EQ(std::count(rows[0].begin(), rows[0].end(), ','), 24);
  EXPECT_EQ(rows[1].rfind("0,0,0.1,0.2,", 0), 0u) << rows[1];
  EXPECT_EQ(rows[2].rfind("0.25,0,0.2,0.4,", 0), 0u) << rows[2];
  EXPECT_EQ(rows[2].substr(rows[2].rfind(',') + 1), "4.6");
}

TEST(TrajectoryWriter, UnfinishedWriterLeavesNothing) {
  TempDir dir;
  const auto scene = small_scene();
  {
    TrajectoryWriter writer(dir.file("t.csv"), *scene);
    writer.write(0.0, Eigen::VectorXd::Zero(24));
  }
  EXPECT_TRUE(dir.entries().empty());
}

TEST(TrajectoryWriter, IncompleteRunKeepsRowsAndSaysWhy) {
  TempDir dir;
  const auto scene = small_scene();
  TrajectoryWriter writer(dir.file("t.csv"), *scene);
  writer.write(0.0, Eigen::VectorXd::Zero(24));
  writer.finish_incomplete("Newton failed\nat t = 0.5");
  const std::vector<std::string> rows = lines(read(dir.file("t.csv")));
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[2], "# stopped early: Newton failed at t = 0.5");
}

TEST(TrajectoryWriter, WrongStateSizeIsABug) {
  TempDir dir;
  const auto scene = small_scene();
  TrajectoryWriter writer(dir.file("t.csv"), *scene);
  EXPECT_THROW(writer.write(0.0, Eigen::VectorXd::Zero(23)), std::logic_error);
}

TEST(TrajectoryWriter, UncreatableFileIsAnInputError) {
  const auto scene = small_scene();
  EXPECT_THROW(TrajectoryWriter("/nonexistent/dir/t.csv", *scene), InputError);
}

TEST(StatsWriter, WritesEveryFieldAndNullForNaN) {
  TempDir dir;
  RunSummary s;
  s.scene = "small";
  s.dofs = Dimensions{6, 6, 0};
  s.report.method = "vie";
  s.report.mode = "error-controlled";
  s.report.linear_solver = "dense-ldlt";
  s.report.linear_solver_reason = "n = 6 <= 200";
  s.report.skipped = {"N(q) products: N = I"};
  s.statistics.steps_taken = 12;
  s.statistics.iteration_matrix_nonzeros = 36;
  s.statistics.factorization_seconds = 0.5;
  s.energy_start = 1.5;
  s.samples = 5;
  s.t_final = 1.0;
  s.t_reached = 1.0;
  {
    StatsWriter writer(dir.file("s.json"));
    EXPECT_FALSE(fs::exists(dir.file("s.json")));
    writer.write(s);
  }
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"s.json"});
  const nlohmann::json j = nlohmann::json::parse(read(dir.file("s.json")));
  EXPECT_EQ(j["scene"], "small");
  EXPECT_EQ(j["dofs"]["nq"], 6);
  EXPECT_EQ(j["integrator"]["method"], "vie");
  EXPECT_EQ(j["integrator"]["linear_solver"]["chosen"], "dense-ldlt");
  EXPECT_EQ(j["integrator"]["linear_solver"]["reason"], "n = 6 <= 200");
  EXPECT_EQ(j["nnz"]["iteration_matrix"], 36);
  EXPECT_EQ(j["wall_time_s"]["factorization"], 0.5);
  EXPECT_EQ(j["statistics"]["steps_taken"], 12);
  EXPECT_EQ(j["statistics"].size(), 83u);  // every IntegratorStatistics field
  EXPECT_TRUE(j["statistics"]["smallest_adapted_step_size_taken"].is_null());
  EXPECT_EQ(j["skipped"][0], "N(q) products: N = I");
  EXPECT_EQ(j["energy"]["start"], 1.5);
  EXPECT_TRUE(j["energy"]["end"].is_null());
  EXPECT_EQ(j["samples"], 5);
  EXPECT_EQ(j["stopped_early"], false);
}

TEST(StatsWriter, UnwrittenStatsLeaveNothing) {
  TempDir dir;
  { StatsWriter writer(dir.file("s.json")); }
  EXPECT_TRUE(dir.entries().empty());
  EXPECT_THROW(StatsWriter("/nonexistent/dir/s.json"), InputError);
}

TEST(VtkWriter, FramesHoldAllNodesAndTheSeriesListsTimes) {
  TempDir dir;
  const auto scene = small_scene();
  // The cloth as two triangles, the rope as its springs.
  VtkWriter writer(dir.file("frames"), *scene, {{}, {{0, 1, 3}, {0, 3, 2}}});
  Eigen::VectorXd x = Eigen::VectorXd::Zero(24);
  x.head(12).setConstant(7.0);   // every free node at (7, 7, 7)
  x.tail(12).setConstant(-1.0);  // every free velocity (-1, -1, -1)
  writer.write_frame(0.0, x);
  writer.write_frame(0.5, x);
  writer.finish();
  EXPECT_EQ(writer.frames(), 2);

  const std::vector<std::string> frame = lines(read(dir.file("frames/small_00001.vtk")));
  ASSERT_GT(frame.size(), 20u);
  EXPECT_EQ(frame[0], "# vtk DataFile Version 3.0");
  EXPECT_EQ(frame[3], "DATASET POLYDATA");
  const auto at = [&](const std::string& line) {
    return std::find(frame.begin(), frame.end(), line) - frame.begin();
  };
  // 3 rope nodes + 4 cloth nodes; pinned nodes at their initial positions
  // (rope node 0 at the origin, cloth nodes 2 and 3 on the row y = 1).
  const long points = at("POINTS 7 double");
  ASSERT_LT(points, static_cast<long>(frame.size()));
  EXPECT_EQ(frame[points + 1], "0 0 0");
  EXPECT_EQ(frame[points + 2], "7 7 7");
  EXPECT_EQ(frame[points + 6], "0 1 0");
  EXPECT_EQ(frame[points + 7], "1 1 0");
  const long polygons = at("POLYGONS 2 8");
  ASSERT_LT(polygons, static_cast<long>(frame.size()));
  EXPECT_EQ(frame[polygons + 1], "3 3 4 6");  // cloth numbering shifted past the rope
  EXPECT_LT(at("LINES 2 6"), static_cast<long>(frame.size()));
  const long velocity = at("VECTORS velocity double");
  ASSERT_LT(velocity, static_cast<long>(frame.size()));
  EXPECT_EQ(frame[velocity + 1], "0 0 0");
  EXPECT_EQ(frame[velocity + 2], "-1 -1 -1");

  const nlohmann::json series = nlohmann::json::parse(read(dir.file("frames/small.vtk.series")));
  EXPECT_EQ(series["file-series-version"], "1.0");
  ASSERT_EQ(series["files"].size(), 2u);
  EXPECT_EQ(series["files"][1]["name"], "small_00001.vtk");
  EXPECT_EQ(series["files"][1]["time"], 0.5);
  for (const auto& e : fs::directory_iterator(dir.file("frames"))) {
    EXPECT_NE(e.path().extension(), ".tmp") << e.path();
  }
}

TEST(VtkWriter, TreesAreDrawnWithTheirPointsVelocities) {
  // A 2-link chain beside a rope: the chain's points are its two body
  // origins, its world anchor and the tip of its last link (scene_drawing.h),
  // joined by three lines; their velocities are the point kinematics'.
  TempDir dir;
  RopeSpec rope;
  rope.name = "rope";
  rope.nodes = 3;
  rope.stretch = SpringParameters{10.0, 0.1};
  std::vector<std::unique_ptr<System>> components;
  components.push_back(std::make_unique<ParticleSystem>(make_rope(rope)));
  auto chain = std::make_unique<ArticulatedSystem>(make_chain_tree(2), ArticulatedOptions{});
  const ArticulatedSystem& arm = *chain;
  components.push_back(std::move(chain));
  const Scene scene("mixed", std::move(components));
  VtkWriter writer(dir.file("frames"), scene);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(scene.dimensions().nx());
  const Dimensions d = scene.dimensions();
  const int q_arm = scene.offsets(1).nq, v_arm = d.nq + scene.offsets(1).nv;
  x[q_arm] = 0.3;
  x[q_arm + 1] = -0.2;
  x[v_arm] = 1.5;
  x[v_arm + 1] = -0.5;
  writer.write_frame(0.0, x);
  writer.finish();
  const std::vector<std::string> frame = lines(read(dir.file("frames/mixed_00000.vtk")));
  const auto at = [&](const std::string& line) {
    return std::find(frame.begin(), frame.end(), line) - frame.begin();
  };
  ASSERT_LT(at("POINTS 7 double"), static_cast<long>(frame.size()));  // 3 nodes + 4
  EXPECT_LT(at("LINES 5 15"), static_cast<long>(frame.size()));       // 2 springs + 3
  const long velocity = at("VECTORS velocity double");
  ASSERT_LT(velocity + 7, static_cast<long>(frame.size()));
  // Point 3 + 1 is the second body's origin, point 3 + 3 the chain's tip.
  PointKinematics pk;
  const Eigen::VectorXd q = x.segment(q_arm, 2), v = x.segment(v_arm, 2);
  arm.point_kinematics(0.0, 1, Eigen::Vector3d::Zero(), q, v, &pk);
  std::istringstream second(frame[velocity + 1 + 3 + 1]);
  Eigen::Vector3d read_back;
  second >> read_back[0] >> read_back[1] >> read_back[2];
  EXPECT_EQ(read_back, pk.p_dot);
  EXPECT_GT(pk.p_dot.norm(), 0.1);
  const long component = at("SCALARS component int 1");
  ASSERT_LT(component + 8, static_cast<long>(frame.size()));
  EXPECT_EQ(frame[component + 2], "0");      // the rope
  EXPECT_EQ(frame[component + 2 + 3], "1");  // the chain: its scene index
}

TEST(VtkWriter, IncompleteSeriesSaysWhy) {
  TempDir dir;
  const auto scene = small_scene();
  VtkWriter writer(dir.file("frames"), *scene);
  writer.write_frame(0.0, Eigen::VectorXd::Zero(24));
  writer.finish_incomplete("diverged");
  const nlohmann::json series = nlohmann::json::parse(read(dir.file("frames/small.vtk.series")));
  EXPECT_EQ(series["stopped_early"], "diverged");
  EXPECT_EQ(series["files"].size(), 1u);
}

}  // namespace
}  // namespace stiffsim
