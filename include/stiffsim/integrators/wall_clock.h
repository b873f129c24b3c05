#pragma once
// Wall-clock intervals for the time split of the statistics.

#include <chrono>

namespace stiffsim {

using WallClock = std::chrono::steady_clock;

inline double seconds_since(WallClock::time_point start) {
  return std::chrono::duration<double>(WallClock::now() - start).count();
}

}  // namespace stiffsim
