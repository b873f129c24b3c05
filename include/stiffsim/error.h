#pragma once
// The two kinds of failure a user sees, with the exit codes of the CLI.

#include <sstream>
#include <stdexcept>
#include <string>

namespace stiffsim {

// A number in a message as a stream prints it (six significant digits: the
// value the user wrote in nearly every case, without a tail of round-off).
inline std::string format_number(double x) {
  std::ostringstream s;
  s << x;
  return s.str();
}

// Malformed or out-of-range input (scene, mesh, URDF, options). The message
// names the file, the line or element and what was expected. Exit code 2.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
  static constexpr int kExitCode = 2;
};

// Numerical trouble during integration (Newton divergence at the minimum
// step, NaN/Inf). The message names the time, the step size, the method and
// the offending state entries. Exit code 3.
class IntegrationError : public std::runtime_error {
 public:
  IntegrationError(const std::string& what, double time, double step)
      : std::runtime_error(what), time_(time), step_(step) {}
  double time() const { return time_; }
  double step() const { return step_; }
  static constexpr int kExitCode = 3;

 private:
  double time_;
  double step_;
};

}  // namespace stiffsim
