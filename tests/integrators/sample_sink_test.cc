// The run loop's sinks: every sink sees the same samples at the sample
// times, a sink that declines stops the run, and ending the sinks reaches
// every one even when an earlier one throws.

#include "stiffsim/integrators/sample_sink.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <vector>

#include "stiffsim/integrators/runge_kutta45.h"
#include "stiffsim/integrators/simulator.h"
#include "test_systems.h"

namespace stiffsim {
namespace {

struct Recording : SampleSink {
  std::vector<double> times;
  std::vector<double> first;  // z of each sample
  int stop_after = -1;        // decline the sample with this index
  std::string ended_with = "<not ended>";
  bool throw_on_end = false;
  bool on_sample(double t, const Eigen::VectorXd& x) override {
    times.push_back(t);
    first.push_back(x[0]);
    return static_cast<int>(times.size()) - 1 != stop_after;
  }
  void on_end(const std::string& reason) override {
    ended_with = reason;
    if (throw_on_end) throw std::runtime_error("disk full");
  }
};

TEST(SampleSinks, EverySinkSeesTheSamplesOfTheClosedForm) {
  // z' = -z: the samples are z0 e^{-t} at t = 0, 0.25, ..., 1.
  LinearTestSystem system(-1.0);
  IntegratorSettings settings;
  settings.accuracy = 1e-10;
  RungeKutta45 integrator(system, settings);
  Recording a, b;
  const SimulationResult result =
      simulate(integrator, system.initial_state(), SimulationSettings{1.0, 0.25}, {&a, &b});
  EXPECT_FALSE(result.stopped_early);
  EXPECT_EQ(result.samples, 5);
  ASSERT_EQ(a.times.size(), 5u);
  EXPECT_EQ(a.times, b.times);
  EXPECT_EQ(a.first, b.first);
  for (size_t k = 0; k < a.times.size(); ++k) {
    EXPECT_DOUBLE_EQ(a.times[k], 0.25 * static_cast<double>(k));
    // Dense output between steps at accuracy 1e-10.
    EXPECT_NEAR(a.first[k], std::exp(-a.times[k]), 1e-8);
  }
  EXPECT_EQ(a.ended_with, "<not ended>");  // the caller ends them
}

TEST(SampleSinks, PeersSampleAtTheTimesTheRunLoopDelivers) {
  // sample_times() is what simulate() delivers after t0, for periods that
  // divide the interval, that do not, and that miss t_final by round-off
  // (0.1 * 3 != 0.3), from a start that is not 0.
  LinearTestSystem system(-1.0);
  struct Case {
    double t0, t_final, period;
    std::vector<double> expected;
  };
  const std::vector<Case> cases = {
      {0.0, 1.0, 0.25, {0.25, 0.5, 0.75, 1.0}},
      {0.0, 1.0, 0.3, {0.3, 0.6, 0.3 * 3, 1.0}},
      {0.0, 0.3, 0.1, {0.1, 0.2, 0.3}},
      {0.5, 1.0, 0.2, {0.7, 0.9, 1.0}},
      {0.0, 1.0, 0.0, {1.0}},
  };
  for (const Case& c : cases) {
    const std::vector<double> times = sample_times(c.t0, c.t_final, c.period);
    EXPECT_EQ(times, c.expected) << c.t0 << " " << c.t_final << " " << c.period;
    if (c.period <= 0.0) continue;  // the loop then samples every step end
    RungeKutta45 integrator(system, IntegratorSettings{});
    Recording run;
    State initial = system.initial_state();
    initial.t = c.t0;
    simulate(integrator, initial, SimulationSettings{c.t_final, c.period}, {&run});
    ASSERT_FALSE(run.times.empty());
    EXPECT_EQ(run.times.front(), c.t0);
    EXPECT_EQ(std::vector<double>(run.times.begin() + 1, run.times.end()), times);
  }
}

TEST(SampleSinks, ADecliningSinkStopsTheRunAfterTheOthersSawTheSample) {
  LinearTestSystem system(-1.0);
  RungeKutta45 integrator(system, IntegratorSettings{});
  Recording a, b;
  b.stop_after = 2;  // t = 0.5
  const SimulationResult result =
      simulate(integrator, system.initial_state(), SimulationSettings{1.0, 0.25}, {&a, &b});
  EXPECT_TRUE(result.stopped_early);
  EXPECT_EQ(a.times.size(), 3u);
  EXPECT_EQ(b.times.size(), 3u);
  EXPECT_DOUBLE_EQ(a.times.back(), 0.5);
}

TEST(SampleSinks, EndingReachesEverySinkAndCollectsTheirErrors) {
  Recording a, b, c;
  b.throw_on_end = true;
  const std::vector<std::string> errors = end_sinks({&a, &b, &c}, "Newton failed");
  EXPECT_EQ(a.ended_with, "Newton failed");
  EXPECT_EQ(b.ended_with, "Newton failed");
  EXPECT_EQ(c.ended_with, "Newton failed");
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_EQ(errors[0], "disk full");
}

}  // namespace
}  // namespace stiffsim
