// End-to-end tests of the stiffsim binary (STIFFSIM_CLI): exit codes,
// messages, and the files a run leaves behind (or does not).

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

std::string read(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::istringstream in(text);
  for (std::string part; std::getline(in, part, separator);) parts.push_back(part);
  return parts;
}

struct Result {
  int exit_code = -1;
  std::string out, err;
};

// Runs the CLI in a fresh temporary directory of the test's own.
class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("stiffsim_cli_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  Result run(const std::string& arguments) const {
    const std::string command = "cd '" + dir_.string() + "' && '" STIFFSIM_CLI "' " + arguments +
                                " >stdout.txt 2>stderr.txt </dev/null";
    const int status = std::system(command.c_str());
    Result r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = read(dir_ / "stdout.txt");
    r.err = read(dir_ / "stderr.txt");
    fs::remove(dir_ / "stdout.txt");
    fs::remove(dir_ / "stderr.txt");
    return r;
  }

  void write(const std::string& name, const std::string& text) const {
    std::ofstream(dir_ / name) << text;
  }

  // Every file in the directory, recursively, except the inputs.
  std::set<std::string> outputs(const std::set<std::string>& inputs) const {
    std::set<std::string> found;
    for (const auto& e : fs::recursive_directory_iterator(dir_)) {
      const std::string name = fs::relative(e.path(), dir_).string();
      if (!inputs.count(name)) found.insert(name);
    }
    return found;
  }

  fs::path dir_;
};

const std::string kModels = std::string(STIFFSIM_SOURCE_DIR) + "/models/";

// A small cloth scene the bad-input cases break one line of.
const char* kSmallCloth = R"(components:
  - name: cloth
    type: cloth
    nodes: [4, 4]
    size: [1.0, 1.0]
    total_mass: 0.4
    stretch: {k: 1.0e3, c: 0.5}
simulation:
  t_final: 0.05
  step: 0.01
)";

std::string with(std::string text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return text.replace(at, from.size(), to);
}

TEST_F(Cli, DefaultSceneWritesTrajectoryAndStats) {
  const Result r =
      run("run '" + kModels + "cloth.yaml' --t-final 0.1 --output t.csv --stats s.json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(outputs({}), (std::set<std::string>{"s.json", "t.csv"}));

  const nlohmann::json stats = nlohmann::json::parse(read(dir_ / "s.json"));
  EXPECT_EQ(stats["scene"], "cloth");
  const int nq = stats["dofs"]["nq"];
  EXPECT_EQ(nq, 3 * (32 * 32 - 2));
  EXPECT_EQ(stats["dofs"]["nv"], nq);
  EXPECT_EQ(stats["integrator"]["method"], "vie");
  EXPECT_EQ(stats["integrator"]["mode"], "error-controlled");
  EXPECT_FALSE(stats["integrator"]["linear_solver"]["chosen"].get<std::string>().empty());
  EXPECT_FALSE(stats["integrator"]["linear_solver"]["reason"].get<std::string>().empty());
  EXPECT_GT(stats["nnz"]["iteration_matrix"].get<long>(), 0);
  for (const char* key :
       {"total", "jacobian", "assembly", "factorization", "solve", "derivative"}) {
    EXPECT_TRUE(stats["wall_time_s"][key].is_number()) << key;
  }
  for (const char* key :
       {"steps_taken", "derivative_evaluations", "derivative_evaluations_for_jacobian",
        "jacobian_evaluations", "iteration_matrix_factorizations", "newton_raphson_iterations",
        "error_estimator_newton_raphson_iterations", "substep_failures",
        "step_shrinkages_from_substep_failures", "step_shrinkages_from_error_control",
        "smallest_adapted_step_size_taken", "largest_step_size_taken",
        "actual_initial_step_size_taken"}) {
    EXPECT_TRUE(stats["statistics"].contains(key)) << key;
  }
  EXPECT_GT(stats["statistics"]["steps_taken"].get<long>(), 0);
  EXPECT_TRUE(stats["energy"]["start"].is_number());
  EXPECT_TRUE(stats["energy"]["end"].is_number());
  // The cloth falls: gravitational energy turns into kinetic, springs damp.
  EXPECT_LT(stats["energy"]["end"].get<double>(), stats["energy"]["start"].get<double>());
  EXPECT_EQ(stats["t_final"], 0.1);
  EXPECT_EQ(stats["stopped_early"], false);
  EXPECT_TRUE(stats["skipped"].is_array());

  const std::vector<std::string> rows = split(read(dir_ / "t.csv"), '\n');
  const std::vector<std::string> header = split(rows.at(0), ',');
  ASSERT_EQ(header.size(), 1u + 2u * nq);
  EXPECT_EQ(header[0], "t");
  EXPECT_EQ(header[1], "q:cloth/n0/x");
  EXPECT_EQ(header[3], "q:cloth/n0/z");
  EXPECT_EQ(header[4], "q:cloth/n1/x");
  EXPECT_EQ(header[1 + nq], "v:cloth/n0/x");
  EXPECT_EQ(header.back(), "v:cloth/n1022/z");  // n1023 is pinned, n1022 the last free node
  EXPECT_EQ(std::count(header.begin(), header.end(), "q:cloth/n992/x"), 0);  // pinned corner
  // One row per sample, every row complete and numeric; 1/60 s sampling
  // to 0.1 s gives t = 0, 1/60, ..., 6/60.
  ASSERT_EQ(static_cast<long>(rows.size()) - 1, stats["samples"].get<long>());
  EXPECT_EQ(rows.size() - 1, 7u);
  for (size_t i = 1; i < rows.size(); ++i) {
    const std::vector<std::string> fields = split(rows[i], ',');
    ASSERT_EQ(fields.size(), header.size()) << "row " << i;
    for (const std::string& f : fields) ASSERT_NO_THROW((void)std::stod(f)) << f;
  }
  EXPECT_EQ(std::stod(split(rows[1], ',')[0]), 0.0);
  EXPECT_DOUBLE_EQ(std::stod(split(rows.back(), ',')[0]), 0.1);
}

TEST_F(Cli, SetChangesTheScene) {
  Result r = run("run '" + kModels +
                 "cloth.yaml' --t-final 0.02 --set cloth.nodes=[4,3] --set "
                 "cloth.stretch.k=2e3 --stats a.json -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Options before the scene file: --set takes one value, not the file too.
  r = run("run --set cloth.nodes=[5,5] --set simulation.t_final=0.02 '" + kModels +
          "cloth.yaml' --stats b.json -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json a = nlohmann::json::parse(read(dir_ / "a.json"));
  const nlohmann::json b = nlohmann::json::parse(read(dir_ / "b.json"));
  EXPECT_EQ(a["dofs"]["nq"], 3 * (12 - 2));
  EXPECT_EQ(b["dofs"]["nq"], 3 * (25 - 2));
  EXPECT_EQ(b["t_final"], 0.02);
}

TEST_F(Cli, OptionsOverrideTheSceneFile) {
  const Result r = run("run '" + kModels +
                       "cloth.yaml' --set cloth.nodes=[4,4] --t-final 0.05 --step 0.01 "
                       "--fixed-step --sample-period 0.025 --accuracy 1e-4 --stats s.json "
                       "--output t.csv --summary");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json s = nlohmann::json::parse(read(dir_ / "s.json"));
  EXPECT_EQ(s["integrator"]["mode"], "fixed-step");
  EXPECT_EQ(s["settings"]["step"], 0.01);
  EXPECT_EQ(s["settings"]["accuracy"], 1e-4);
  EXPECT_EQ(s["samples"], 3);  // t = 0, 0.025, 0.05
  EXPECT_EQ(s["statistics"]["steps_taken"], 5);
  EXPECT_EQ(split(read(dir_ / "t.csv"), '\n').size(), 4u);
  // The summary names what a reader wants first.
  for (const char* fragment : {"scene          cloth", "dofs           nq 42", "vie, fixed-step",
                               "Newton iterations", "factorizations", "Jacobian evaluations",
                               "linear solver", "wall time", "energy         start"}) {
    EXPECT_NE(r.out.find(fragment), std::string::npos) << fragment << "\n" << r.out;
  }
}

TEST_F(Cli, NewtonToleranceOfFixedStepsIsTheStepsErrorUnlessAsked) {
  // The 8x8 cloth at 1/60: by default the solves converge to the steps' own
  // error (counted), with --newton-tolerance accuracy to the accuracy's
  // tolerance, which takes more Newton iterations.
  const std::string common = "run '" + kModels +
                             "cloth.yaml' --set cloth.nodes=[8,8] --t-final 0.5 --fixed-step "
                             "--step 0.016666666666666666 --newton-solve chord -q";
  Result r = run(common + " --stats wide.json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run(common + " --newton-tolerance accuracy --stats tight.json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json wide = nlohmann::json::parse(read(dir_ / "wide.json"))["statistics"];
  const nlohmann::json tight = nlohmann::json::parse(read(dir_ / "tight.json"))["statistics"];
  EXPECT_GT(wide["newton_tolerance_from_step_error"].get<long>(), 0);
  EXPECT_EQ(tight["newton_tolerance_from_step_error"].get<long>(), 0);
  EXPECT_LT(wide["newton_raphson_iterations"].get<long>(),
            tight["newton_raphson_iterations"].get<long>());
  r = run(common + " --newton-tolerance loose");
  EXPECT_EQ(r.exit_code, 2);
}

TEST_F(Cli, PreconditionerPrecisionIsChosenAndReported) {
  // The 32x32 cloth's supernodal factor: GMRES's preconditioner solves run
  // in single precision by default and in double when asked, and the stats
  // say which.
  const std::string common = "run '" + kModels +
                             "cloth.yaml' --t-final 0.2 --fixed-step "
                             "--step 0.016666666666666666 --newton-solve krylov -q";
  Result r = run(common + " --stats single.json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run(common + " --preconditioner-precision double --stats double.json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json single = nlohmann::json::parse(read(dir_ / "single.json"));
  const nlohmann::json twice = nlohmann::json::parse(read(dir_ / "double.json"));
  EXPECT_EQ(single["integrator"]["preconditioner_precision"], "single");
  EXPECT_EQ(twice["integrator"]["preconditioner_precision"], "double");
  EXPECT_GT(single["statistics"]["krylov_iterations"].get<long>(), 0);
  EXPECT_EQ(single["statistics"]["single_precision_solves"].get<long>(),
            single["statistics"]["krylov_iterations"].get<long>() +
                single["statistics"]["chord_solves"].get<long>() -
                single["statistics"]["krylov_chord_starts"].get<long>());
  // The Krylov path's preconditioners are factored in double, full
  // Newton's (without the bend springs' couplings) in float unless asked.
  EXPECT_EQ(single["statistics"]["single_precision_factorizations"].get<long>(), 0);
  const std::string fresh = "run '" + kModels +
                            "cloth.yaml' --t-final 0.1 --fixed-step "
                            "--step 0.016666666666666666 --newton-solve fresh -q";
  r = run(fresh + " --stats fresh_single.json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run(fresh + " --preconditioner-precision double --stats fresh_double.json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json fresh_single =
      nlohmann::json::parse(read(dir_ / "fresh_single.json"))["statistics"];
  const nlohmann::json fresh_double =
      nlohmann::json::parse(read(dir_ / "fresh_double.json"))["statistics"];
  EXPECT_GT(fresh_single["single_precision_factorizations"].get<long>(), 0);
  EXPECT_EQ(fresh_single["single_precision_factorizations"].get<long>(),
            fresh_single["covered_coupling_factorizations"].get<long>());
  EXPECT_EQ(fresh_double["single_precision_factorizations"].get<long>(), 0);
  EXPECT_GT(twice["statistics"]["krylov_iterations"].get<long>(), 0);
  EXPECT_EQ(twice["statistics"]["single_precision_solves"].get<long>(), 0);
  r = run(common + " --preconditioner-precision half");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--preconditioner-precision"), std::string::npos) << r.err;
}

TEST_F(Cli, VerifyRootsChecksEverySolveAndChangesNothingElse) {
  // The 8x8 cloth at 1/60 on the chord path (its choices depend on counts,
  // not timings): with --verify-roots every solve is checked and the
  // largest distance reported; the trajectory is the same byte for byte.
  const std::string common = "run '" + kModels +
                             "cloth.yaml' --set cloth.nodes=[8,8] --t-final 0.25 --fixed-step "
                             "--step 0.016666666666666666 --newton-solve chord -q";
  Result r = run(common + " --stats plain.json --output plain.csv");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run(common + " --verify-roots --stats checked.json --output checked.csv");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read(dir_ / "plain.csv"), read(dir_ / "checked.csv"));
  const nlohmann::json plain = nlohmann::json::parse(read(dir_ / "plain.json"))["statistics"];
  const nlohmann::json checked = nlohmann::json::parse(read(dir_ / "checked.json"))["statistics"];
  EXPECT_EQ(plain["root_checks"].get<long>(), 0);
  EXPECT_TRUE(plain["largest_root_distance_ratio"].is_null());
  EXPECT_EQ(checked["root_checks"].get<long>(), checked["newton_solves"].get<long>());
  EXPECT_GE(checked["largest_root_distance_ratio"].get<double>(), 0.0);
  EXPECT_EQ(checked["newton_raphson_iterations"], plain["newton_raphson_iterations"]);
}

TEST_F(Cli, VtkWritesFramesAndASeries) {
  const Result r = run("run '" + kModels +
                       "cloth.yaml' --set cloth.nodes=[4,3] --t-final 0.05 --vtk frames "
                       "--stats s.json -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const long samples = nlohmann::json::parse(read(dir_ / "s.json"))["samples"];
  EXPECT_EQ(samples, 4);  // t = 0, 1/60, 2/60, 0.05
  std::set<std::string> expected = {"cloth.vtk.series"};
  for (long i = 0; i < samples; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "cloth_%05ld.vtk", i);
    expected.insert(name);
  }
  std::set<std::string> found;
  for (const auto& e : fs::directory_iterator(dir_ / "frames")) found.insert(e.path().filename());
  EXPECT_EQ(found, expected);
  const std::string frame = read(dir_ / "frames/cloth_00002.vtk");
  EXPECT_EQ(frame.rfind("# vtk DataFile Version 3.0\n", 0), 0u);
  EXPECT_NE(frame.find("\nPOINTS 12 double\n"), std::string::npos);  // pinned nodes included
  EXPECT_NE(frame.find("\nPOLYGONS 12 48\n"), std::string::npos);    // 2 per grid cell
  const nlohmann::json series = nlohmann::json::parse(read(dir_ / "frames/cloth.vtk.series"));
  ASSERT_EQ(series["files"].size(), static_cast<size_t>(samples));
  EXPECT_EQ(series["files"][3]["name"], "cloth_00003.vtk");
  EXPECT_DOUBLE_EQ(series["files"][3]["time"].get<double>(), 0.05);
}

TEST_F(Cli, OtherShippedScenesRun) {
  for (const char* scene : {"rope.yaml", "sheet.yaml"}) {
    const Result r = run("run '" + kModels + scene + "' --t-final 0.02 --stats s.json -q");
    EXPECT_EQ(r.exit_code, 0) << scene << ": " << r.err;
  }
}

TEST_F(Cli, BadScenesExitTwoNameFileAndKeyAndLeaveNoFiles) {
  struct Case {
    std::string name, text, fragment;
  };
  const std::vector<Case> cases = {
      {"malformed.yaml", with(kSmallCloth, "nodes: [4, 4]", "nodes: [4, 4"), "malformed.yaml:5:"},
      {"typo.yaml", with(kSmallCloth, "stretch:", "strech:"),
       "typo.yaml:7:5: components[0] (cloth): unknown key 'strech'"},
      {"mesh.yaml", "components:\n  - {name: sheet, type: mesh, file: missing.obj, density: 0.2}\n",
       "mesh.yaml:2:37: components[0] (sheet): mesh file 'missing.obj' not found"},
      {"mass.yaml", with(kSmallCloth, "total_mass: 0.4", "total_mass: -0.4"),
       "mass.yaml:6:17: components[0] (cloth): total_mass must be positive"},
      {"zero.yaml", with(kSmallCloth, "nodes: [4, 4]", "nodes: [0, 4]"),
       "zero.yaml:4:13: components[0] (cloth): nodes[0] must be at least 2"},
      {"nan.yaml", with(kSmallCloth, "size: [1.0, 1.0]", "size: [1.0, .nan]"),
       "nan.yaml:5:17: components[0] (cloth): size[1] must be a finite number"},
      {"urdf.yaml", "components:\n  - {name: arm, type: urdf, file: chain_10.urdf}\n",
       "urdf.yaml:2:35: components[0] (arm): URDF file 'chain_10.urdf' not found"},
  };
  std::set<std::string> inputs;
  for (const Case& c : cases) {
    write(c.name, c.text);
    inputs.insert(c.name);
  }
  for (const Case& c : cases) {
    const Result r = run("run " + c.name + " --output t.csv --stats s.json --vtk frames");
    EXPECT_EQ(r.exit_code, 2) << c.name << ": " << r.err;
    EXPECT_EQ(r.err.rfind("stiffsim: error: " + c.fragment, 0), 0u) << c.name << ": " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_TRUE(outputs(inputs).empty()) << c.name << " left files behind";
  }
}

TEST_F(Cli, BadSetExitsTwoAndLeavesNoFiles) {
  const Result r = run("run '" + kModels + "cloth.yaml' --set cloth.stretch.kk=1 --output t.csv");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--set cloth.stretch.kk=1: unknown key 'cloth.stretch.kk'"),
            std::string::npos)
      << r.err;
  EXPECT_TRUE(outputs({}).empty());
}

TEST_F(Cli, BareUrdfWithoutLinksExitsTwoNamingTheFile) {
  write("chain.urdf", "<robot name='chain'/>\n");
  const Result r = run("run chain.urdf --output t.csv");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err.rfind("stiffsim: error: chain.urdf: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("No link elements"), std::string::npos) << r.err;
  EXPECT_TRUE(outputs({"chain.urdf"}).empty());
}

TEST_F(Cli, BareUrdfRunsWithJointColumns) {
  const Result r = run("run '" + kModels + "chain_2.urdf' --t-final 0.1 --set chain_2.initial.all_joints=0.3 "
                       "--output t.csv -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream in(dir_ / "t.csv");
  std::string header;
  while (std::getline(in, header) && header.rfind("#", 0) == 0) {
  }
  EXPECT_EQ(header, "t,q:chain_2/joint_1,q:chain_2/joint_2,v:chain_2/joint_1,v:chain_2/joint_2");
}

TEST_F(Cli, MissingSceneFileExitsTwo) {
  const Result r = run("run nothere.yaml");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.err, "stiffsim: error: nothere.yaml: cannot open\n");
}

TEST_F(Cli, UsageErrorsExitTwo) {
  const std::vector<std::string> bad = {
      "",                                  // no subcommand
      "run",                               // no scene
      "walk x.yaml",                       // unknown subcommand
      "run x.yaml --bogus",                // unknown option
      "run x.yaml --accuracy 2",           // out of (0, 1]
      "run x.yaml --t-final nan",          // not finite
      "run x.yaml --t-final -1",           // not positive
      "run x.yaml --jacobian exact",       // not a scheme
      "run x.yaml --linear-solver mumps",  // not a solver
      "run x.yaml --integrator rk99",      // not an integrator
  };
  for (const std::string& arguments : bad) {
    const Result r = run(arguments);
    EXPECT_EQ(r.exit_code, 2) << arguments << ": " << r.err;
    EXPECT_EQ(r.err.rfind("stiffsim: error: ", 0), 0u) << arguments << ": " << r.err;
  }
  EXPECT_TRUE(outputs({}).empty());
}

TEST_F(Cli, HelpDescribesEveryOption) {
  Result r = run("--help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("run"), std::string::npos);
  r = run("run --help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* option : {"SCENE",
                             "--integrator",
                             "--t-final",
                             "--step",
                             "--fixed-step",
                             "--error-estimate",
                             "--accuracy",
                             "--jacobian",
                             "--linear-solver",
                             "--newton-form",
                             "--newton-tolerance",
                             "step-error",
                             "--preconditioner-precision",
                             "--full-newton",
                             "--no-reuse",
                             "--verify-roots",
                             "--output",
                             "--sample-period",
                             "--stats",
                             "--vtk",
                             "--set",
                             "--quiet",
                             "--summary",
                             "analytic,forward,central,automatic",
                             "Exit codes"}) {
    EXPECT_NE(r.out.find(option), std::string::npos) << option;
  }
}

TEST_F(Cli, IntegrationFailureExitsThreeAndKeepsTheRowsSoFar) {
  // Stretch springs of 1e12 N/m at a minimum step of 1/60 s: Newton cannot
  // converge and the step may not shrink, so the run must stop.
  const Result r = run("run '" + kModels +
                       "cloth.yaml' --set cloth.nodes=[4,4] --set cloth.stretch.k=1e12 --set "
                       "simulation.min_step=0.016 --t-final 0.5 --output t.csv --stats s.json");
  ASSERT_EQ(r.exit_code, 3) << r.err;
  EXPECT_EQ(r.err.rfind("stiffsim: error: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("t = "), std::string::npos) << r.err;
  const std::vector<std::string> rows = split(read(dir_ / "t.csv"), '\n');
  ASSERT_GE(rows.size(), 3u);  // header, the sample at t = 0, the footer
  EXPECT_EQ(rows.back().rfind("# stopped early: ", 0), 0u) << rows.back();
  const nlohmann::json s = nlohmann::json::parse(read(dir_ / "s.json"));
  EXPECT_EQ(s["stopped_early"], true);
  EXPECT_EQ(s["samples"].get<size_t>(), rows.size() - 2);
  EXPECT_EQ(outputs({}), (std::set<std::string>{"s.json", "t.csv"}));
}

TEST_F(Cli, UnwritableOutputExitsTwoBeforeRunning) {
  const Result r = run("run '" + kModels + "cloth.yaml' --output nodir/t.csv --stats s.json");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("nodir/t.csv: cannot create"), std::string::npos) << r.err;
  EXPECT_TRUE(outputs({}).empty());
}

}  // namespace

TEST_F(Cli, EveryIntegratorAndJacobianSchemeRuns) {
  write("small.yaml", kSmallCloth);
  for (const std::string method : {"vie", "vie2", "ie", "ie2", "rk3", "rk45"}) {
    const Result r = run("run small.yaml --integrator " + method + " --stats s.json");
    ASSERT_EQ(r.exit_code, 0) << method << ": " << r.err;
    const nlohmann::json s = nlohmann::json::parse(read(dir_ / "s.json"));
    EXPECT_EQ(s["integrator"]["method"], method);
    EXPECT_EQ(s["integrator"]["extrapolated"], method == "vie2" || method == "ie2") << method;
  }
  const Result euler =
      run("run small.yaml --integrator semi-explicit-euler --fixed-step --step 1e-3");
  EXPECT_EQ(euler.exit_code, 0) << euler.err;
  for (const std::string scheme : {"forward", "central", "automatic"}) {
    const Result r = run("run small.yaml --jacobian " + scheme + " --stats s.json");
    ASSERT_EQ(r.exit_code, 0) << scheme << ": " << r.err;
    const nlohmann::json s = nlohmann::json::parse(read(dir_ / "s.json"));
    EXPECT_EQ(s["integrator"]["jacobian_scheme"], scheme);
    EXPECT_EQ(s["integrator"].contains("jacobian_colours"), scheme != "automatic") << scheme;
  }
  const Result ie = run("run small.yaml --integrator ie --error-estimator doubling --stats s.json");
  ASSERT_EQ(ie.exit_code, 0) << ie.err;
  EXPECT_EQ(nlohmann::json::parse(read(dir_ / "s.json"))["integrator"]["error_estimator"],
            "step doubling");
}

TEST_F(Cli, ExplicitMethodOnAStiffClothStopsWithTimeAndStep) {
  // k = 1e6 N/m at h = 1/60 s is far beyond any explicit method's stability
  // limit: the run must stop with exit code 3, not write a blown-up state.
  const Result r = run("run '" + kModels +
                       "cloth_stiff.yaml' --set cloth.nodes=[6,6] --integrator rk45 --output t.csv");
  ASSERT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("rk45"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("t = "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("h = "), std::string::npos) << r.err;
  // Every row written is finite and of the size of the cloth (1 m, a few
  // m/s): the blow-up is caught before it reaches the file.
  const std::vector<std::string> rows = split(read(dir_ / "t.csv"), '\n');
  ASSERT_GE(rows.size(), 3u);
  EXPECT_EQ(rows.back().rfind("# stopped early: ", 0), 0u) << rows.back();
  for (size_t i = 1; i + 1 < rows.size(); ++i) {
    for (const std::string& cell : split(rows[i], ',')) {
      const double value = std::stod(cell);
      ASSERT_TRUE(std::isfinite(value)) << rows[i];
      ASSERT_LT(std::abs(value), 1e3) << "row " << i;
    }
  }
}

TEST_F(Cli, SigintStopsCleanlyAndKeepsCompleteRows) {
  // A run far longer than the 2 s after which timeout(1) sends SIGINT.
  const std::string command = "cd '" + dir_.string() + "' && timeout --preserve-status -s INT 2 '" +
                              STIFFSIM_CLI "' run '" + kModels +
                              "cloth.yaml' --t-final 1000 --output t.csv --stats s.json -q "
                              ">stdout.txt 2>stderr.txt </dev/null";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);
  const std::string err = read(dir_ / "stderr.txt");
  EXPECT_NE(err.find("interrupted by SIGINT at t = "), std::string::npos) << err;
  const std::vector<std::string> rows = split(read(dir_ / "t.csv"), '\n');
  ASSERT_GE(rows.size(), 3u);
  EXPECT_EQ(rows.back().rfind("# stopped early: interrupted by SIGINT", 0), 0u) << rows.back();
  // Every data row is complete: as many cells as the header.
  const size_t columns = split(rows[0], ',').size();
  for (size_t i = 1; i + 1 < rows.size(); ++i) EXPECT_EQ(split(rows[i], ',').size(), columns);
  const nlohmann::json s = nlohmann::json::parse(read(dir_ / "s.json"));
  EXPECT_EQ(s["stopped_early"], true);
  EXPECT_EQ(s["samples"].get<size_t>(), rows.size() - 2);
  // No temporary file is left behind.
  EXPECT_EQ(outputs({"stdout.txt", "stderr.txt"}), (std::set<std::string>{"s.json", "t.csv"}));
}
