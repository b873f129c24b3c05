#pragma once
// A prescribed scalar motion p(t) and its rate p'(t): a joint drive's
// target, one coordinate of a moving anchor. Either a constant, piecewise
// linear through keyframes (held at the first value before the first key
// and at the last after the last; its rate is the slope of the segment, so
// position and velocity targets agree), or a sinusoid
//   p(t) = offset + amplitude sin(2 pi frequency t + phase).

#include <string>
#include <vector>

namespace stiffsim {

class ScalarPath {
 public:
  // p(t) = value.
  static ScalarPath constant(double value);
  // Keyframes (t_k, p_k) with strictly increasing times; throws
  // InputError naming `what` when they are empty, not finite or out of
  // order.
  static ScalarPath keyframes(std::vector<double> times, std::vector<double> values,
                              const std::string& what);
  static ScalarPath sinusoid(double offset, double amplitude, double frequency, double phase,
                             const std::string& what);

  double value(double t) const;
  double rate(double t) const;
  // p''(t): zero inside keyframe segments, whose rate jumps at every key
  // (see has_continuous_rate()).
  double acceleration(double t) const;
  bool is_constant() const { return kind_ == Kind::kConstant; }
  // False for keyframes: what follows such a path takes an impulse at each
  // key, which acceleration() does not carry.
  bool has_continuous_rate() const { return kind_ != Kind::kKeyframes; }

 private:
  enum class Kind { kConstant, kKeyframes, kSinusoid };
  // The keyframe segment [times_[k], times_[k + 1]) holding t, or -1 before
  // the first key and size - 1 after the last.
  int segment(double t) const;

  Kind kind_ = Kind::kConstant;
  double offset_ = 0.0, amplitude_ = 0.0, omega_ = 0.0, phase_ = 0.0;
  std::vector<double> times_, values_;
};

}  // namespace stiffsim
