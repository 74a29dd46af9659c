#include "emulator/campaign/run_pool.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <stdexcept>
#include <system_error>
#include <thread>

namespace wheelhil::emulator::campaign {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct Running {
  pid_t pid = -1;
  int slot = 0;  // 0 .. jobs-1, free again when the run ends
  PoolJob job;
  Clock::time_point start;
  bool timed_out = false;
  std::string error;  // set when the run could not start
};

// fork + exec with the child in its own process group, dying with us.
pid_t Spawn(const std::vector<std::string>& argv, const fs::path& log_file) {
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const int log_fd = ::open(log_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (log_fd < 0) return -1;
  // Made before the fork: the child of a threaded process may only make async-signal-safe
  // calls (no allocation) before its exec.
  const std::string cannot = fmt::format("cannot execute {}: ", argv[0]);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::setpgid(0, 0);
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);  // parent already gone
    ::dup2(log_fd, STDOUT_FILENO);
    ::dup2(log_fd, STDERR_FILENO);
    const int null_fd = ::open("/dev/null", O_RDONLY);
    if (null_fd >= 0) ::dup2(null_fd, STDIN_FILENO);
    ::execv(args[0], args.data());
    // strerrordesc_np: a constant string, no locale, no allocation.
    const char* why = ::strerrordesc_np(errno);
    if (why == nullptr) why = "exec failed";
    (void)!::write(STDERR_FILENO, cannot.data(), cannot.size());
    (void)!::write(STDERR_FILENO, why, std::strlen(why));
    (void)!::write(STDERR_FILENO, "\n", 1);
    ::_exit(127);
  }
  ::close(log_fd);
  if (pid > 0) ::setpgid(pid, pid);  // also from the parent: no race with an early kill
  return pid;
}

std::string LastLine(const fs::path& file) {
  FILE* f = std::fopen(file.c_str(), "r");
  if (!f) return "";
  std::string last, line;
  char buf[512];
  while (std::fgets(buf, sizeof buf, f)) {
    line += buf;
    if (!line.empty() && line.back() == '\n') {
      line.pop_back();
      if (!line.empty()) last = line;
      line.clear();
    }
  }
  if (!line.empty()) last = line;
  std::fclose(f);
  if (last.size() > 300) last = last.substr(0, 300) + "...";
  return last;
}

class Progress {
 public:
  Progress(const PoolOptions& o, std::size_t total)
      : enabled_(o.progress),
        tty_(::isatty(STDERR_FILENO) == 1),
        label_(o.label),
        total_(total),
        start_(Clock::now()) {}
  void Finished(const RunRecord& r) {
    ++done_;
    if (!r.passed) ++failed_;
    if (!enabled_) return;
    const double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
    const double eta = done_ ? elapsed / done_ * (total_ - done_) : 0;
    if (tty_) {
      constexpr int kWidth = 30;
      const int filled = total_ ? static_cast<int>(kWidth * done_ / total_) : kWidth;
      std::string bar(filled, '#');
      bar += std::string(kWidth - filled, '.');
      std::fprintf(stderr, "\r%s [%s] %zu/%zu done, %zu failed, ETA %s  ", label_.c_str(),
                   bar.c_str(), done_, total_, failed_, FormatDuration(eta).c_str());
      if (done_ == total_) std::fputc('\n', stderr);
    } else {
      std::fprintf(stderr, "%s: %zu/%zu %s %s (%.1f s)%s%s, %zu failed, ETA %s\n", label_.c_str(),
                   done_, total_, r.key.c_str(), r.passed ? "pass" : "FAIL", r.wall_s,
                   r.passed ? "" : ": ", r.passed ? "" : r.failure.substr(0, 200).c_str(), failed_,
                   FormatDuration(eta).c_str());
    }
    std::fflush(stderr);
  }

 private:
  bool enabled_, tty_;
  std::string label_;
  std::size_t total_, done_ = 0, failed_ = 0;
  Clock::time_point start_;
};

}  // namespace

std::string ThisExecutable() {
  std::error_code ec;
  const auto p = fs::read_symlink("/proc/self/exe", ec);
  if (ec) throw std::runtime_error("cannot read /proc/self/exe: " + ec.message());
  return p.string();
}

std::string FormatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) seconds = 0;
  const long s = std::lround(seconds);
  if (s >= 3600) return fmt::format("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60);
  return fmt::format("{}:{:02}", s / 60, s % 60);
}

std::vector<RunRecord> RunPool(
    std::vector<PoolJob> jobs, const PoolOptions& options,
    const std::function<void(RunRecord&, const RunReport* report)>& evaluate,
    const std::function<void(const RunRecord&)>& done) {
  if (options.jobs < 1) throw std::invalid_argument("--jobs must be >= 1");
  std::vector<RunRecord> finished;
  std::deque<PoolJob> queue(std::make_move_iterator(jobs.begin()),
                            std::make_move_iterator(jobs.end()));
  std::vector<Running> running;
  Progress progress(options, queue.size());

  auto finish = [&](Running& r, int status) {
    RunRecord rec = r.job.record;
    rec.wall_s = std::chrono::duration<double>(Clock::now() - r.start).count();
    rec.report_path = (fs::path(rec.run_dir) / "report.json").string();
    std::optional<RunReport> report;
    if (!r.error.empty()) {
      rec.verdict = "error";
      rec.exit_code = -1;
      rec.failure = r.error;
    } else {
      rec.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      std::string why;
      if (!r.timed_out) report = ReadRunReport(rec.report_path, &why);
      if (r.timed_out) {
        rec.verdict = "timeout";
        rec.failure = fmt::format("run exceeded timeout_s = {} and was killed", r.job.timeout_s);
      } else if (!report) {
        rec.verdict = "error";
        rec.failure = fmt::format("runner exit code {}, {}; {}: {}", rec.exit_code, why,
                                  (fs::path(rec.run_dir) / "runner.log").string(),
                                  LastLine(fs::path(rec.run_dir) / "runner.log"));
      } else {
        rec.verdict = report->verdict;
        rec.metrics = report->metrics;
      }
    }
    if (!report) rec.report_path.clear();
    rec.passed = report && report->VerdictPassed();
    evaluate(rec, report ? &*report : nullptr);
    done(rec);
    progress.Finished(rec);
    finished.push_back(std::move(rec));
  };

  std::vector<int> cpus;  // the CPUs this process may use
  if (cpu_set_t allowed; ::sched_getaffinity(0, sizeof(allowed), &allowed) == 0) {
    for (int c = 0; c < CPU_SETSIZE; ++c) {
      if (CPU_ISSET(c, &allowed)) cpus.push_back(c);
    }
  }
  while (!queue.empty() || !running.empty()) {
    while (!queue.empty() && static_cast<int>(running.size()) < options.jobs) {
      Running r;
      r.job = std::move(queue.front());
      queue.pop_front();
      r.start = Clock::now();
      const fs::path run_dir = r.job.record.run_dir;
      try {
        fs::remove_all(run_dir);  // leftovers of an interrupted attempt
        fs::create_directories(run_dir);
        const fs::path scenario = r.job.prepare(run_dir);
        r.job.record.scenario_path = scenario.string();
        std::vector<std::string> argv = {options.runner_exe,
                                         "run",
                                         scenario.string(),
                                         "--out",
                                         run_dir.string(),
                                         "--seed",
                                         std::to_string(r.job.record.seed)};
        argv.insert(argv.end(), options.extra_args.begin(), options.extra_args.end());
        for (int slot = 0;; ++slot) {
          if (std::none_of(running.begin(), running.end(),
                           [&](const Running& o) { return o.slot == slot; })) {
            r.slot = slot;
            break;
          }
        }
        if (options.spread_cpus && !cpus.empty() &&
            std::find(argv.begin(), argv.end(), "--cpu") == argv.end()) {
          argv.push_back("--cpu");
          argv.push_back(std::to_string(cpus[static_cast<std::size_t>(r.slot) % cpus.size()]));
        }
        // As many runs as CPUs: a run's physics thread would only take another run's CPU.
        if (!cpus.empty() && static_cast<std::size_t>(options.jobs) >= cpus.size() &&
            std::find(argv.begin(), argv.end(), "--physics-thread") == argv.end()) {
          argv.push_back("--physics-thread");
          argv.push_back("off");
        }
        r.pid = Spawn(argv, run_dir / "runner.log");
        if (r.pid < 0) {
          throw std::runtime_error(
              fmt::format("cannot start {}: {}", options.runner_exe, std::strerror(errno)));
        }
      } catch (const std::exception& e) {
        r.error = e.what();
        finish(r, 0);
        continue;
      }
      running.push_back(std::move(r));
    }
    bool reaped = false;
    for (std::size_t i = 0; i < running.size();) {
      int status = 0;
      const pid_t got = ::waitpid(running[i].pid, &status, WNOHANG);
      if (got == running[i].pid) {
        ::kill(-running[i].pid, SIGKILL);  // grandchildren left in the run's group
        Running r = std::move(running[i]);
        running.erase(running.begin() + static_cast<std::ptrdiff_t>(i));
        finish(r, status);
        reaped = true;
        continue;
      }
      if (got < 0 && errno != EINTR) {
        Running r = std::move(running[i]);
        running.erase(running.begin() + static_cast<std::ptrdiff_t>(i));
        r.error = fmt::format("waitpid: {}", std::strerror(errno));
        finish(r, 0);
        reaped = true;
        continue;
      }
      const double age = std::chrono::duration<double>(Clock::now() - running[i].start).count();
      if (!running[i].timed_out && age > running[i].job.timeout_s) {
        running[i].timed_out = true;
        ::kill(-running[i].pid, SIGKILL);
      }
      ++i;
    }
    if (!reaped && !running.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return finished;
}

}  // namespace wheelhil::emulator::campaign
