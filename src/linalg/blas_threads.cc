#include "stiffsim/linalg/blas_threads.h"

#include <cholmod.h>
#include <dlfcn.h>
#include <link.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <mutex>

#include "stiffsim/linalg/blas_kernels.h"

// Weak: resolved only when the BLAS behind libblas.so.3 is OpenBLAS, so the
// reference BLAS still links and runs.
extern "C" void openblas_set_num_threads(int) __attribute__((weak));
// OpenBLAS's (pthread build) shutdown of its thread pool; a later call with
// more threads starts the pool again.
extern "C" int blas_thread_shutdown_() __attribute__((weak));
// Weak as well: resolved when an OpenMP runtime is loaded (libgomp, through
// CHOLMOD), so stiffsim still links and runs without one.
extern "C" void omp_set_num_threads(int) __attribute__((weak));
extern "C" void omp_set_max_active_levels(int) __attribute__((weak));
extern "C" int omp_get_max_active_levels() __attribute__((weak));

namespace stiffsim {
namespace {

constexpr int kDefaultThreads = 1;

std::mutex process_mutex;             // orders the process-wide writes below
std::atomic<int> process_threads{0};  // 0: neither set nor defaulted yet
std::atomic<bool> set_explicitly{false};
// The count this thread's OpenMP settings were last given; 0 for none.
thread_local int thread_openmp_threads = 0;
std::atomic<long> regions_run_inline{0};

// The addresses of CHOLMOD's code: the executable segments of the loaded
// object that holds cholmod_start. Empty when none is found.
struct CodeRange {
  std::uintptr_t begin = 0, end = 0;
  bool contains(std::uintptr_t address) const { return address >= begin && address < end; }
};

CodeRange cholmod_code() {
  struct Search {
    std::uintptr_t target;
    CodeRange found;
  } search{reinterpret_cast<std::uintptr_t>(&cholmod_start), {}};
  dl_iterate_phdr(
      [](dl_phdr_info* info, std::size_t, void* data) {
        auto* s = static_cast<Search*>(data);
        CodeRange code{UINTPTR_MAX, 0};
        for (int k = 0; k < info->dlpi_phnum; ++k) {
          const ElfW(Phdr)& segment = info->dlpi_phdr[k];
          if (segment.p_type != PT_LOAD || !(segment.p_flags & PF_X)) continue;
          const std::uintptr_t begin = info->dlpi_addr + segment.p_vaddr;
          code.begin = std::min(code.begin, begin);
          code.end = std::max<std::uintptr_t>(code.end, begin + segment.p_memsz);
        }
        if (!code.contains(s->target)) return 0;
        s->found = code;
        return 1;
      },
      &search);
  return search.found;
}

bool apply_openblas(int threads) {
  if (openblas_set_num_threads == nullptr) return false;
  openblas_set_num_threads(threads);
  // OpenBLAS starts a server thread per core when it loads, and each spins
  // (sched_yield) for its timeout, about 0.1 s, after it starts and after
  // every job before it sleeps; a lower count leaves them so. On one
  // thread none is used: the pool is shut down. Measured: a process
  // sleeping 0.5 s after its BLAS calls used 0.20 s of CPU with the pool
  // left at one thread, 0.05 s with it shut down; a one-step run of
  // cloth_stiff.yaml 0.10-0.11 s of system time on the other core, against
  // 0.01-0.03 s.
  if (threads == 1 && blas_thread_shutdown_ != nullptr) blas_thread_shutdown_();
  return true;
}

void apply_openmp(int threads) {
  thread_openmp_threads = threads;
  if (omp_set_max_active_levels != nullptr) {
    // libgomp runs a region on one thread when the current active level
    // reaches max-active-levels, whatever its num_threads clause says.
    const int levels = omp_get_max_active_levels != nullptr ? omp_get_max_active_levels() : 0;
    omp_set_max_active_levels(threads == 1 ? 0 : std::max(levels, 1));
  }
  if (omp_set_num_threads != nullptr) omp_set_num_threads(threads);
}

}  // namespace

bool set_blas_threads(int threads) {
  choose_blas_kernels();
  threads = std::max(threads, 1);
  bool told;
  {
    const std::lock_guard<std::mutex> lock(process_mutex);
    told = apply_openblas(threads);
    set_explicitly = true;
    process_threads = threads;
  }
  apply_openmp(threads);
  return told;
}

void apply_blas_threads() {
  int threads = process_threads.load();
  if (threads == 0) {
    choose_blas_kernels();
    const std::lock_guard<std::mutex> lock(process_mutex);
    if (process_threads.load() == 0) {
      apply_openblas(kDefaultThreads);
      process_threads = kDefaultThreads;
    }
    threads = process_threads.load();
  }
  if (thread_openmp_threads != threads) apply_openmp(threads);
}

int current_blas_threads() { return process_threads.load(); }

long openmp_regions_run_inline() { return regions_run_inline.load(std::memory_order_relaxed); }

bool blas_threads_set_explicitly() { return set_explicitly.load(); }

}  // namespace stiffsim

// GCC compiles `#pragma omp parallel` into a call of GOMP_parallel, and
// libgomp's runs even a one-thread region as a team: it allocates and
// clears the team and wakes its barrier by a system call at the end, some
// microseconds each. CHOLMOD's supernodal factorization opens a region for
// nearly every supernode (to clear it and to assemble A into it), so with
// one thread that overhead was a quarter of the factorization of a 32x32
// cloth's matrix (BM_Factorize/32: 4.2-4.5 ms, 3.3-3.4 ms inline) and a
// tenth of cloth_stiff.yaml's run time in the kernel. This definition,
// found before libgomp's, runs CHOLMOD's regions as a direct call where
// the calling thread was given one thread (apply_openmp): a region run on
// one thread outside any team is OpenMP's orphaned case, whose loops and
// barriers behave as the team of one does. Every other caller, and CHOLMOD
// with more threads, goes to libgomp.
extern "C" void GOMP_parallel(void (*fn)(void*), void* data, unsigned num_threads, unsigned flags) {
  using Parallel = void (*)(void (*)(void*), void*, unsigned, unsigned);
  static const stiffsim::CodeRange cholmod = stiffsim::cholmod_code();
  static const auto next = reinterpret_cast<Parallel>(dlsym(RTLD_NEXT, "GOMP_parallel"));
  const auto caller = reinterpret_cast<std::uintptr_t>(__builtin_return_address(0));
  if (next == nullptr || (stiffsim::thread_openmp_threads == 1 && cholmod.contains(caller))) {
    stiffsim::regions_run_inline.fetch_add(1, std::memory_order_relaxed);
    fn(data);
    return;
  }
  next(fn, data, num_threads, flags);
}
