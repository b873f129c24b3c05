#include "stiffsim/reports/child_process_run.h"

#include <fcntl.h>
#include <malloc.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <type_traits>

namespace stiffsim {
namespace {

// The child is a fork of this very process image, so the bytes of a
// trivially copyable value mean the same on both ends: no format to version.
class PayloadWriter {
 public:
  template <typename T>
  void put(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    bytes_.append(reinterpret_cast<const char*>(&value), sizeof value);
  }
  void put(const std::string& text) {
    put(text.size());
    bytes_.append(text);
  }
  void put(const Eigen::VectorXd& x) {
    put(static_cast<Eigen::Index>(x.size()));
    bytes_.append(reinterpret_cast<const char*>(x.data()), sizeof(double) * x.size());
  }
  template <typename T>
  void put(const std::vector<T>& items) {
    put(items.size());
    for (const T& item : items) put(item);
  }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string bytes_;
};

// Reads what PayloadWriter wrote; ok() turns false at the first read past
// the end (a child that died while writing).
class PayloadReader {
 public:
  explicit PayloadReader(const std::string& bytes) : bytes_(bytes) {}
  template <typename T>
  void get(T* value) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (take(sizeof *value)) std::memcpy(value, bytes_.data() + at_ - sizeof *value, sizeof *value);
  }
  void get(std::string* text) {
    std::size_t size = 0;
    get(&size);
    if (take(size)) *text = bytes_.substr(at_ - size, size);
  }
  void get(Eigen::VectorXd* x) {
    Eigen::Index size = 0;
    get(&size);
    if (size < 0 || !take(sizeof(double) * size)) return;
    x->resize(size);
    std::memcpy(x->data(), bytes_.data() + at_ - sizeof(double) * size, sizeof(double) * size);
  }
  template <typename T>
  void get(std::vector<T>* items) {
    std::size_t size = 0;
    get(&size);
    items->clear();
    for (std::size_t i = 0; i < size && ok_; ++i) get(&items->emplace_back());
  }
  bool ok() const { return ok_; }
  bool at_end() const { return at_ == bytes_.size(); }

 private:
  bool take(std::size_t n) {
    ok_ = ok_ && n <= bytes_.size() - at_;
    if (ok_) at_ += n;
    return ok_;
  }
  const std::string& bytes_;
  std::size_t at_ = 0;
  bool ok_ = true;
};

// Every field of MethodRun but peak_resident_mb, which the parent measures.
// A field added to MethodRun changes its size (here, libstdc++ on x86-64):
// add it to both functions, then update the size.
static_assert(sizeof(MethodRun) == 1632, "MethodRun changed: update write_run() and read_run()");

std::string write_run(const MethodRun& r) {
  PayloadWriter w;
  w.put(r.spec.method), w.put(r.spec.fixed), w.put(r.spec.parameter);
  w.put(r.times), w.put(r.samples), w.put(r.wall_seconds);
  w.put(r.steps), w.put(r.newton_iterations), w.put(r.factorizations), w.put(r.newton_failures);
  w.put(r.derivative_evaluations), w.put(r.stats), w.put(r.linear_solver), w.put(r.settings);
  w.put(r.finished), w.put(r.over_budget), w.put(r.message);
  w.put(r.energy_start), w.put(r.energy_max), w.put(r.energy_end), w.put(r.kinetic_max);
  w.put(r.non_finite), w.put(r.first_step_wall_seconds), w.put(r.first_step_stats);
  return w.bytes();
}

bool read_run(const std::string& bytes, MethodRun* r) {
  PayloadReader in(bytes);
  in.get(&r->spec.method), in.get(&r->spec.fixed), in.get(&r->spec.parameter);
  in.get(&r->times), in.get(&r->samples), in.get(&r->wall_seconds);
  in.get(&r->steps), in.get(&r->newton_iterations), in.get(&r->factorizations);
  in.get(&r->newton_failures), in.get(&r->derivative_evaluations), in.get(&r->stats);
  in.get(&r->linear_solver), in.get(&r->settings);
  in.get(&r->finished), in.get(&r->over_budget), in.get(&r->message);
  in.get(&r->energy_start), in.get(&r->energy_max), in.get(&r->energy_end);
  in.get(&r->kinetic_max), in.get(&r->non_finite), in.get(&r->first_step_wall_seconds);
  in.get(&r->first_step_stats);
  return in.ok() && in.at_end();
}

bool write_all(int fd, const std::string& bytes) {
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    done += static_cast<std::size_t>(n);
  }
  return true;
}

[[noreturn]] void run_child(const std::function<MethodRun()>& body, int fd) {
  // When the machine runs out of memory the kernel ends the process with
  // the highest score: let that be this run, not the report or a program
  // beside it.
  if (std::FILE* score = std::fopen("/proc/self/oom_score_adj", "w")) {
    std::fputs("1000", score);
    std::fclose(score);
  }
  MethodRun run;
  try {
    run = body();
  } catch (const std::exception& e) {
    run = MethodRun{};
    run.message = e.what();
  } catch (...) {
    run = MethodRun{};
    run.message = "the run threw an exception that is not a std::exception";
  }
  _exit(write_all(fd, write_run(run)) ? 0 : 3);
}

std::string signal_name(int signal) {
  const char* name = strsignal(signal);
  return std::to_string(signal) + " (" + (name ? name : "unknown") + ")";
}

}  // namespace

MethodRun run_in_child_process(const std::function<MethodRun()>& body,
                               const ChildProcessOptions& options) {
  MethodRun run;
#ifdef __GLIBC__
  // Pages this process freed but glibc kept would be resident in the child
  // from its first instant, counted as the run's: give them back first.
  malloc_trim(0);
#endif
  int fds[2];
  if (pipe2(fds, O_CLOEXEC) != 0) {
    run.message = std::string("cannot open a pipe for the run's process: ") + std::strerror(errno);
    return run;
  }
  const auto start = std::chrono::steady_clock::now();
  // libgomp (behind CHOLMOD) cannot run a parallel region in a child forked
  // after one ran here; at the default of one thread (blas_threads.h) it
  // never starts a team.
  const pid_t pid = fork();
  if (pid < 0) {
    run.message = std::string("cannot start a process for the run: ") + std::strerror(errno);
    close(fds[0]), close(fds[1]);
    return run;
  }
  if (pid == 0) {
    close(fds[0]);
    run_child(body, fds[1]);
  }
  close(fds[1]);
  auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };

  // Read until the child closes its end (it exited), or until its time is up.
  std::string bytes;
  bool killed = false;
  std::string lost;  // why this process stopped listening, when not the time limit
  char buffer[1 << 16];
  for (;;) {
    int timeout_ms = -1;
    if (options.kill_after_seconds > 0.0) {
      const double left = options.kill_after_seconds - elapsed();
      if (left <= 0.0) {
        kill(pid, SIGKILL);
        killed = true;
        break;
      }
      timeout_ms = static_cast<int>(std::min(left, 1e6) * 1e3) + 1;
    }
    pollfd p{fds[0], POLLIN, 0};
    const int ready = poll(&p, 1, timeout_ms);
    if (ready < 0 && errno == EINTR) continue;
    const ssize_t n = ready > 0 ? read(fds[0], buffer, sizeof buffer) : 0;
    if (n < 0 && errno == EINTR) continue;
    if (ready < 0 || n < 0) {
      // Waiting for a child nobody reads from could hang: end it.
      lost = std::strerror(errno);
      kill(pid, SIGKILL);
      break;
    }
    if (ready == 0) continue;
    if (n == 0) break;
    bytes.append(buffer, static_cast<std::size_t>(n));
  }
  close(fds[0]);
  int status = 0;
  rusage usage{};
  while (wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {
  }
  const double wall = elapsed();

  char text[192];
  if (killed) {
    run.over_budget = true;
    std::snprintf(text, sizeof text, "killed at its %g s time limit, still running",
                  options.kill_after_seconds);
    run.message = text;
    run.wall_seconds = wall;
  } else if (!lost.empty()) {
    run.message = "lost the run's process: " + lost;
    run.wall_seconds = wall;
  } else if (WIFSIGNALED(status)) {
    run.message = "the run's process died of signal " + signal_name(WTERMSIG(status));
    if (WTERMSIG(status) == SIGKILL) {
      run.message += ", which is how the kernel ends a process when memory runs out";
    }
    run.wall_seconds = wall;
  } else if (!WIFEXITED(status) || WEXITSTATUS(status) != 0 || !read_run(bytes, &run)) {
    run = MethodRun{};
    std::snprintf(text, sizeof text, "the run's process exited (status %d) without its result",
                  WIFEXITED(status) ? WEXITSTATUS(status) : -1);
    run.message = text;
    run.wall_seconds = wall;
  }
  // Linux gives ru_maxrss in kilobytes.
  run.peak_resident_mb = static_cast<double>(usage.ru_maxrss) / 1024.0;
  return run;
}

}  // namespace stiffsim
