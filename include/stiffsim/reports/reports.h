#pragma once
// The three reports of `stiffsim bench` (DESIGN.md section 8): error against
// run time (precision), time per step against size (scaling), and stiff and
// extreme cases (stability). Each writes CSV and a Markdown summary into
// `out_dir`; bench/plot_reports.py draws the PNGs from the CSVs.

#include <ostream>
#include <string>

namespace stiffsim {

struct ReportOptions {
  bool quick = false;          // the CI preset: small scenes, fewer points
  std::string out_dir = "bench/results";
  std::string models_dir;      // where chain_10.urdf is (MuJoCo loads the file)
  std::ostream* log = nullptr;  // progress lines; null: quiet
};

// Each returns 0, or throws InputError for an unusable out_dir.
int run_precision_report(const ReportOptions& options);
int run_scaling_report(const ReportOptions& options);
int run_stability_report(const ReportOptions& options);

}  // namespace stiffsim
