#include "stiffsim/linalg/blas_kernels.h"

#include <strings.h>

#include <cstdlib>
#include <mutex>
#include <string>

// Weak: resolved only when the BLAS behind libblas.so.3 is OpenBLAS built
// with DYNAMIC_ARCH (its runtime kernel choice), so any other BLAS still
// links and runs.
extern "C" char* openblas_get_corename() __attribute__((weak));
extern "C" void gotoblas_dynamic_init() __attribute__((weak));
extern "C" void gotoblas_dynamic_quit() __attribute__((weak));

namespace stiffsim {
namespace {

std::once_flag chosen;
std::string note;  // written once, under `chosen`

// The best of OpenBLAS's x86-64 kernel sets the CPU and the OS support
// (libgcc's feature test checks the OS saves the wide registers), or null.
const char* kernels_for_this_cpu(const char** why) {
#if defined(__x86_64__)
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
      __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512vl")) {
    *why = "AVX-512";
    return "SkylakeX";
  }
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) {
    *why = "AVX2 and FMA";
    return "Haswell";
  }
  if (__builtin_cpu_supports("avx")) {
    *why = "AVX";
    return "Sandybridge";
  }
#endif
  (void)why;
  return nullptr;
}

std::string corename() {
  const char* name = openblas_get_corename();
  return name != nullptr ? name : "";
}

void choose() {
  if (openblas_get_corename == nullptr) return;  // not OpenBLAS
  const std::string found = corename();
  note = "OpenBLAS " + found;
  if (strcasecmp(found.c_str(), "Prescott") != 0) return;  // it knew the CPU
  if (std::getenv("OPENBLAS_CORETYPE") != nullptr) {
    note += " (OPENBLAS_CORETYPE as given)";
    return;
  }
  const char* why = "";
  const char* better = kernels_for_this_cpu(&why);
  if (better == nullptr || gotoblas_dynamic_init == nullptr || gotoblas_dynamic_quit == nullptr) {
    return;
  }
  setenv("OPENBLAS_CORETYPE", better, 1);
  gotoblas_dynamic_quit();
  gotoblas_dynamic_init();
  unsetenv("OPENBLAS_CORETYPE");
  note = "OpenBLAS " + corename() + ", chosen for " + why + " (OpenBLAS's own choice: " + found +
         ", its fallback for a CPU it does not know)";
}

}  // namespace

void choose_blas_kernels() { std::call_once(chosen, choose); }

std::string blas_kernels_note() { return note; }

std::string blas_kernels_in_use() { return openblas_get_corename != nullptr ? corename() : ""; }

}  // namespace stiffsim
