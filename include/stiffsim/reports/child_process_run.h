#pragma once
// One run in a process of its own, forked from the report: the only way to
// say how much memory that run needed. The report's own resident set is the
// same figure for every run (glibc keeps the heap an earlier, larger run
// freed), and the allocator's counters see neither the peak (mallinfo2 only
// has the current total, and glibc has no malloc hooks since 2.34) nor the
// memory that does not come from malloc (BLAS buffers, stacks). The kernel
// records the peak resident set of each process, whatever allocated it, and
// wait4 returns it for that one child (getrusage(RUSAGE_CHILDREN) would give
// the largest over all children instead). The child also keeps a run that
// crashes, runs out of memory or never returns from a step from taking the
// report down with it.

#include <functional>

#include "stiffsim/reports/method_run.h"

namespace stiffsim {

struct ChildProcessOptions {
  // Wall time after which the child is killed, as a run over its budget:
  // a run checks its budget between steps, which does not help when one
  // step takes hours. 0: never.
  double kill_after_seconds = 0.0;
};

// Runs `body` in a child forked from this process and returns the run it
// returned, with peak_resident_mb set to the child's peak resident set
// (ru_maxrss). That peak includes the pages the child shares with this
// process at the fork (the program, and what this process holds alive: a
// scene built before the call counts for the run), but not the heap this
// process has freed, which is given back to the system before the fork.
// A child that throws, dies of a signal or is killed at kill_after_seconds
// gives a run with finished = false and the reason in message. The child
// ends with _exit: it never runs this process's exit handlers nor flushes
// its stdio buffers twice.
MethodRun run_in_child_process(const std::function<MethodRun()>& body,
                               const ChildProcessOptions& options);

}  // namespace stiffsim
