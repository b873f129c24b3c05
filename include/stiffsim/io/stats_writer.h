#pragma once
// The stats JSON of DESIGN.md section 8: what ran, on how many DOFs, which
// work it did (every IntegratorStatistics counter under its own name), where
// the time went and the energy at start and end. NaN (undefined) numbers are
// written as null.

#include <limits>
#include <string>

#include "stiffsim/integrators/integrator_statistics.h"
#include "stiffsim/state.h"

namespace stiffsim {

struct RunSummary {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  std::string scene;
  Dimensions dofs;
  IntegratorReport report;
  IntegratorStatistics statistics;
  double accuracy = kNaN;  // target accuracy of the run
  double step = kNaN;      // maximum (or fixed) step
  double sample_period = kNaN;
  double wall_seconds = 0.0;   // the whole simulation loop, writers included
  double energy_start = kNaN;  // NaN where the scene defines no energy
  double energy_end = kNaN;    // at the last sample
  long samples = 0;
  double t_final = kNaN;    // requested end time
  double t_reached = kNaN;  // time of the last sample
  bool stopped_early = false;
  std::string stop_reason;  // empty unless stopped_early
};

// The JSON document, pretty-printed.
std::string stats_json(const RunSummary& summary);
// Its "statistics" object alone, on one line: every counter of `statistics`
// under the name it has in the file (for front ends that show them live).
std::string statistics_json(const IntegratorStatistics& statistics);

// Reserves "<path>.tmp" at construction, so that an unwritable path is an
// error before the run rather than after it; write() fills it and renames it
// to <path>. Destroyed without write(), it removes the temporary file.
class StatsWriter {
 public:
  // Throws InputError if the file cannot be created.
  explicit StatsWriter(std::string path);
  ~StatsWriter();
  StatsWriter(const StatsWriter&) = delete;
  StatsWriter& operator=(const StatsWriter&) = delete;

  // Throws std::runtime_error on a write error, leaving no file behind.
  void write(const RunSummary& summary);
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::string temp_path_;
  bool pending_ = false;  // the temporary file exists and is ours to remove
};

}  // namespace stiffsim
