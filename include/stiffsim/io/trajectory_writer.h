#pragma once
// The trajectory CSV of DESIGN.md section 8: `t`, then `q:<name>` per
// position, `v:<name>` per velocity and `z:<name>` per miscellaneous state,
// one row per sample, every number in shortest round-trip form (reading it
// back gives the same double).
//
// Rows go to "<path>.tmp", which is renamed to <path> only by finish() or
// finish_incomplete(): a run that is killed leaves no file under the name the
// user asked for, and one that fails leaves a file that says so in its last
// line.

#include <Eigen/Core>
#include <cstdio>
#include <string>
#include <vector>

#include "stiffsim/integrators/sample_sink.h"
#include "stiffsim/system.h"

namespace stiffsim {

// The header of the CSV, one name per column: "t", then "q:<name>",
// "v:<name>" and "z:<name>" in the order of x = [q; v; z].
std::vector<std::string> trajectory_columns(const System& system);

class TrajectoryWriter : public FileSink {
 public:
  // As a run's sink every sample is a row; the run's end finishes the file.
  bool on_sample(double t, const Eigen::VectorXd& x) override {
    write(t, x);
    return true;
  }

  // Creates "<path>.tmp" and writes the header. Throws InputError if the file
  // cannot be created (e.g. its directory does not exist).
  TrajectoryWriter(const std::string& path, const System& system);
  // Without finish(), removes the temporary file.
  ~TrajectoryWriter();
  TrajectoryWriter(const TrajectoryWriter&) = delete;
  TrajectoryWriter& operator=(const TrajectoryWriter&) = delete;

  // One row: t and the state x = [q; v; z] (size nq + nv + nz).
  void write(double t, const Eigen::VectorXd& x);
  // Flushes, closes and renames to the final path. Throws std::runtime_error
  // on a write error (disk full), leaving no file behind.
  void finish() override;
  // As finish(), after a footer line "# stopped early: <reason>" so that the
  // rows so far are kept but cannot be mistaken for a complete run.
  void finish_incomplete(const std::string& reason) override;

  const std::string& path() const { return path_; }
  long rows() const { return rows_; }

 private:
  void flush_buffer();
  void close_and_rename();

  std::string path_;
  std::string temp_path_;
  std::FILE* file_ = nullptr;
  long columns_ = 0;
  long rows_ = 0;
  std::string buffer_;  // one row at a time; reused so writing a row does not allocate
};

// Shortest decimal form of `value` that parses back to the same double
// ("0.1", "1e-05", "nan", "inf"). Appends to `out`.
void append_number(double value, std::string* out);

}  // namespace stiffsim
