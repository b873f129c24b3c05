#include "stiffsim/model/path.h"

#include <algorithm>
#include <cmath>

#include "stiffsim/error.h"

namespace stiffsim {

ScalarPath ScalarPath::constant(double value) {
  ScalarPath p;
  p.offset_ = value;
  return p;
}

ScalarPath ScalarPath::keyframes(std::vector<double> times, std::vector<double> values,
                                 const std::string& what) {
  if (times.empty() || times.size() != values.size()) {
    throw InputError(what + ": expected at least one keyframe [t, value]");
  }
  for (std::size_t k = 0; k < times.size(); ++k) {
    if (!std::isfinite(times[k]) || !std::isfinite(values[k])) {
      throw InputError(what + ": keyframe " + std::to_string(k) + " is not finite");
    }
    if (k > 0 && !(times[k] > times[k - 1])) {
      throw InputError(what + ": keyframe times must increase; keyframe " + std::to_string(k) +
                       " (t = " + std::to_string(times[k]) + ") does not come after keyframe " +
                       std::to_string(k - 1) + " (t = " + std::to_string(times[k - 1]) + ")");
    }
  }
  ScalarPath p;
  p.kind_ = times.size() == 1 ? Kind::kConstant : Kind::kKeyframes;
  p.offset_ = values.front();
  p.times_ = std::move(times);
  p.values_ = std::move(values);
  return p;
}

ScalarPath ScalarPath::sinusoid(double offset, double amplitude, double frequency, double phase,
                                const std::string& what) {
  if (!std::isfinite(offset) || !std::isfinite(amplitude) || !std::isfinite(frequency) ||
      !std::isfinite(phase) || frequency < 0.0) {
    throw InputError(what +
                     ": a sinusoid needs finite offset, amplitude and phase and a "
                     "frequency >= 0");
  }
  ScalarPath p;
  p.kind_ = Kind::kSinusoid;
  p.offset_ = offset;
  p.amplitude_ = amplitude;
  p.omega_ = 2.0 * M_PI * frequency;
  p.phase_ = phase;
  return p;
}

int ScalarPath::segment(double t) const {
  // upper_bound: the first key after t, so a key's own time starts the
  // segment that follows it.
  const auto it = std::upper_bound(times_.begin(), times_.end(), t);
  return static_cast<int>(it - times_.begin()) - 1;
}

double ScalarPath::value(double t) const {
  switch (kind_) {
    case Kind::kConstant:
      return offset_;
    case Kind::kSinusoid:
      return offset_ + amplitude_ * std::sin(omega_ * t + phase_);
    case Kind::kKeyframes: {
      const int k = segment(t);
      if (k < 0) return values_.front();
      if (k + 1 >= static_cast<int>(times_.size())) return values_.back();
      const double s = (t - times_[k]) / (times_[k + 1] - times_[k]);
      return values_[k] + s * (values_[k + 1] - values_[k]);
    }
  }
  return offset_;
}

double ScalarPath::rate(double t) const {
  switch (kind_) {
    case Kind::kConstant:
      return 0.0;
    case Kind::kSinusoid:
      return amplitude_ * omega_ * std::cos(omega_ * t + phase_);
    case Kind::kKeyframes: {
      const int k = segment(t);
      if (k < 0 || k + 1 >= static_cast<int>(times_.size())) return 0.0;
      return (values_[k + 1] - values_[k]) / (times_[k + 1] - times_[k]);
    }
  }
  return 0.0;
}

double ScalarPath::acceleration(double t) const {
  if (kind_ != Kind::kSinusoid) return 0.0;
  return -amplitude_ * omega_ * omega_ * std::sin(omega_ * t + phase_);
}

}  // namespace stiffsim
