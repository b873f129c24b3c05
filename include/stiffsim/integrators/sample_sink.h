#pragma once
// Where a run's samples go. The run loop (simulate()) hands each sample to
// every sink of the run, and the caller ends them all once with the reason
// the run stopped; the trajectory CSV, the VTK frames, the reports' sample
// recorders and the CLI's run summary are sinks alike, so no caller feeds or
// finishes its outputs by hand.

#include <Eigen/Core>
#include <string>
#include <vector>

namespace stiffsim {

class SampleSink {
 public:
  virtual ~SampleSink() = default;
  // One sample: time t, state x = [q; v; z]. Returns false to stop the run
  // after this sample.
  virtual bool on_sample(double t, const Eigen::VectorXd& x) = 0;
  // The run is over: `reason` is empty when it reached t_final, else why it
  // stopped (a file sink then marks its output incomplete). Throws if the
  // output cannot be completed.
  virtual void on_end(const std::string& reason) { (void)reason; }
};

// A sink that writes a file: completed by finish(), or by
// finish_incomplete(reason), which keeps what was written but marks it as
// the output of a run that stopped early.
class FileSink : public SampleSink {
 public:
  void on_end(const std::string& reason) override {
    if (reason.empty()) {
      finish();
    } else {
      finish_incomplete(reason);
    }
  }
  virtual void finish() = 0;
  virtual void finish_incomplete(const std::string& reason) = 0;
};

// Ends every sink with `reason`, each even if an earlier one throws, and
// returns the messages of those that did (e.g. a full disk).
std::vector<std::string> end_sinks(const std::vector<SampleSink*>& sinks,
                                   const std::string& reason);

}  // namespace stiffsim
