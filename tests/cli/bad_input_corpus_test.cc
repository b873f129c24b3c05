// Runs the stiffsim binary (STIFFSIM_CLI) on every broken input file of
// tests/data/bad/ and checks the contract of README.md "Exit codes": exit code
// 2, one "stiffsim: error: " line that names the file and says what was wrong
// (the manifest expected.txt gives a fragment of it per file), and no output
// file written.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

const fs::path kCorpus = fs::path(STIFFSIM_SOURCE_DIR) / "tests" / "data" / "bad";
const char* kManifest = "expected.txt";
// The folder under kCorpus that holds the broken OBJ meshes; they are run
// through the scenes that reference them, not on their own.
const char* kMeshes = "meshes";
constexpr size_t kMinimumCases = 40;

std::string read(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

struct Case {
  std::string file;      // relative to kCorpus
  std::string fragment;  // must appear in the error message
  int line = 0;          // in the manifest, for messages
};

// One "<file> TAB <fragment>" per line; blank lines and lines starting with
// '#' are skipped. A malformed line becomes a case with an empty fragment,
// which the manifest test reports.
std::vector<Case> read_manifest() {
  std::vector<Case> cases;
  std::istringstream in(read(kCorpus / kManifest));
  int number = 0;
  for (std::string line; std::getline(in, line);) {
    ++number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    const size_t tab = line.find('\t');
    Case c;
    c.line = number;
    c.file = line.substr(0, tab);
    if (tab != std::string::npos) c.fragment = line.substr(tab + 1);
    cases.push_back(c);
  }
  return cases;
}

void PrintTo(const Case& c, std::ostream* out) { *out << c.file; }

TEST(BadInputManifest, CoversTheWholeFolder) {
  const std::vector<Case> cases = read_manifest();
  EXPECT_GE(cases.size(), kMinimumCases);

  std::set<std::string> listed;
  for (const Case& c : cases) {
    EXPECT_FALSE(c.fragment.empty())
        << kManifest << ":" << c.line << ": expected '<file> TAB <message fragment>'";
    EXPECT_TRUE(listed.insert(c.file).second)
        << kManifest << ":" << c.line << ": " << c.file << " is listed twice";
    EXPECT_TRUE(fs::is_regular_file(kCorpus / c.file))
        << kManifest << ":" << c.line << ": no file " << c.file;
  }

  // Every input in the folder is run, so a case cannot be added and forgotten.
  std::string scenes;  // all manifest scenes, to find the meshes they reference
  for (const auto& entry : fs::directory_iterator(kCorpus)) {
    const std::string name = entry.path().filename().string();
    if (name == kManifest || name == kMeshes) continue;
    EXPECT_TRUE(listed.count(name)) << name << " is in " << kCorpus << " but not in " << kManifest;
    if (listed.count(name)) scenes += read(entry.path());
  }
  for (const auto& entry : fs::directory_iterator(kCorpus / kMeshes)) {
    const std::string name = std::string(kMeshes) + "/" + entry.path().filename().string();
    EXPECT_NE(scenes.find(name), std::string::npos)
        << name << " is referenced by no scene of " << kManifest;
  }
}

class BadInput : public ::testing::TestWithParam<Case> {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = info->name();
    std::replace(name.begin(), name.end(), '/', '_');
    dir_ = fs::temp_directory_path() / ("stiffsim_bad_" + name + "_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    // The run's own directory holds nothing else, so anything found in it
    // afterwards was written by the run.
    fs::create_directories(dir_ / "run");
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path dir_;
};

TEST_P(BadInput, FailsWithOneClearMessage) {
  const Case& c = GetParam();
  const std::string input = (kCorpus / c.file).string();
  const std::string command = "cd '" + (dir_ / "run").string() + "' && '" STIFFSIM_CLI "' run '" +
                              input + "' --output out.csv --stats out.json >'" +
                              (dir_ / "stdout.txt").string() + "' 2>'" +
                              (dir_ / "stderr.txt").string() + "' </dev/null";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status)) << c.file << ": the CLI did not exit normally (status " << status
                                 << ")";
  const std::string err = read(dir_ / "stderr.txt");
  SCOPED_TRACE(kManifest + std::string(":") + std::to_string(c.line) + ": " + c.file +
               "\nstderr: " + err);

  EXPECT_EQ(WEXITSTATUS(status), 2);
  EXPECT_EQ(err.rfind("stiffsim: error: ", 0), 0u);
  EXPECT_NE(err.find(input), std::string::npos) << "the message does not name the file";
  EXPECT_NE(err.find(c.fragment), std::string::npos) << "expected: " << c.fragment;
  // One line: the first problem found, not a cascade of follow-up errors.
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1);
  EXPECT_FALSE(err.empty() || err.back() != '\n');

  std::vector<std::string> written;
  for (const auto& e : fs::recursive_directory_iterator(dir_ / "run")) {
    written.push_back(fs::relative(e.path(), dir_ / "run").string());
  }
  EXPECT_TRUE(written.empty()) << "wrote " << written.front();
}

// "obj_index_zero.yaml" -> "obj_index_zero_yaml": gtest names allow only
// letters, digits and '_'.
std::string case_name(const ::testing::TestParamInfo<Case>& info) {
  std::string name = info.param.file;
  for (char& ch : name) {
    if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
  }
  return name;
}

INSTANTIATE_TEST_SUITE_P(Corpus, BadInput, ::testing::ValuesIn(read_manifest()), case_name);

}  // namespace
