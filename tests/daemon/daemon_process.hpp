// ds1928d as its own process (simulated bus, a config file written by the test), for the tests
// that watch what the daemon process does: its exit, its memory, its log, its shm.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>

#include "ds1928/shm.hpp"
#include "support/unix_socket.hpp"
#include "support/wait.hpp"

namespace ds1928::test {

// Under AddressSanitizer the daemon's memory is not the daemon's alone: every live block carries
// redzones and shadow, and every freed block waits in ASan's quarantine (256 MiB by default) so
// that a use after free is caught, which makes RSS grow with every block freed. The daemons started
// here run with a quarantine of kAsanQuarantineMb, and a test's memory bound is widened by
// asan_memory_bound_kb: three times the bound (redzones, shadow) plus the quarantine. Leaks are
// LeakSanitizer's to find in that build; the exact bound is checked in the normal build.
#if defined(__SANITIZE_ADDRESS__)
inline constexpr long kAsanQuarantineMb = 8;
[[nodiscard]] constexpr long memory_bound_kb(long bound_kb) {
  return 3 * bound_kb + kAsanQuarantineMb * 1024;
}
#else
[[nodiscard]] constexpr long memory_bound_kb(long bound_kb) { return bound_kb; }
#endif

class DaemonProcess {
 public:
  // `socket_extra`: more keys of the socket section, YAML flow style ("max_clients: 100");
  // `extra_yaml`: more top-level lines ("metrics: {listen: off}\n").
  DaemonProcess(const std::string& tag, const std::string& socket_extra,
                const std::string& extra_yaml = {}) {
    char tmpl[] = "/tmp/ds1928d-proc-XXXXXX";
    if (mkdtemp(tmpl) == nullptr) return;
    dir_ = tmpl;
    shm_name_ = "/ds1928d-proc-" + tag + "-" + std::to_string(::getpid());
    socket_path_ = dir_ + "/control.sock";
    {
      std::ofstream f(dir_ + "/ds1928d.yaml");
      f << "bus: simulated\n"
        << "cycle: {period_us: 1000, hold_cpu_dma_latency: false}\n"
        << "axes: [{name: x}, {name: y, slot: 2}]\n"
        << "shm: {name: " << shm_name_ << "}\n"
        << "socket: {path: " << socket_path_ << (socket_extra.empty() ? "" : ", ") << socket_extra
        << "}\n"
        << extra_yaml;
    }
    pid_ = fork();
    if (pid_ == 0) {
      const int log = ::open((dir_ + "/log").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
      if (log >= 0) {
        dup2(log, STDOUT_FILENO);
        dup2(log, STDERR_FILENO);
      }
      // Log to the file, not to a journal the test runner may have; no readiness protocol.
      unsetenv("JOURNAL_STREAM");
      unsetenv("NOTIFY_SOCKET");
      unsetenv("WATCHDOG_USEC");
#if defined(__SANITIZE_ADDRESS__)
      {
        const char* inherited = std::getenv("ASAN_OPTIONS");
        const std::string options = std::string(inherited != nullptr ? inherited : "") +
                                    ":quarantine_size_mb=" + std::to_string(kAsanQuarantineMb);
        setenv("ASAN_OPTIONS", options.c_str(), 1);
      }
#endif
      execl(DS1928D, DS1928D, "-c", (dir_ + "/ds1928d.yaml").c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
  }

  ~DaemonProcess() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      // A daemon that ignores SIGTERM fails the test elsewhere; here it must not outlive it.
      (void)ds1928::test::wait_until([&] { return !running(); });
      if (running()) {
        ::kill(pid_, SIGKILL);
        waitpid(pid_, nullptr, 0);
      }
    }
    reader_.close();
    if (!shm_name_.empty()) {
      shm_unlink(shm_name_.c_str());
      shm_unlink((shm_name_ + DS1928_SHM_WAIT_SUFFIX).c_str());
    }
    std::error_code ec;
    if (!dir_.empty()) std::filesystem::remove_all(dir_, ec);
  }
  DaemonProcess(const DaemonProcess&) = delete;
  DaemonProcess& operator=(const DaemonProcess&) = delete;

  // Waits (bounded, support/wait.hpp) until the daemon publishes cycles and its socket accepts.
  [[nodiscard]] bool wait_ready() {
    bool ready = false;
    (void)ds1928::test::wait_until([&] {
      if (!running()) return true;  // gone: no use waiting
      if (!reader_.is_open()) (void)reader_.open(shm_name_);
      ready = reader_.is_open() && reader_.header().publish_count > 0 &&
              unix_socket_accepts(socket_path_);
      return ready;
    });
    return ready;
  }

  // Still running (not exited, not killed by a signal).
  [[nodiscard]] bool running() {
    if (pid_ <= 0) return false;
    int status = 0;
    const pid_t r = waitpid(pid_, &status, WNOHANG);
    if (r == 0) return true;
    if (r == pid_) {
      exit_status_ = status;
      pid_ = -1;
    }
    return false;
  }
  [[nodiscard]] std::optional<int> exit_status() const { return exit_status_; }

  // A line of /proc/PID/status in kB ("VmHWM", "VmRSS"); -1 when unreadable.
  [[nodiscard]] long vm_kb(const std::string& key) const {
    std::ifstream f("/proc/" + std::to_string(pid_) + "/status");
    std::string line;
    while (std::getline(f, line)) {
      if (line.rfind(key + ":", 0) == 0)
        return std::strtol(line.c_str() + key.size() + 1, nullptr, 10);
    }
    return -1;
  }

  [[nodiscard]] std::string log() const {
    std::ifstream f(dir_ + "/log");
    std::stringstream s;
    s << f.rdbuf();
    return s.str();
  }

  // How many times `needle` is in the log once it reaches `expected` or the bound (wait.hpp)
  // runs out: the daemon's logger is asynchronous, so a line for what a client just saw happen
  // (its connection closed) is written a moment later, by the logger's own thread.
  [[nodiscard]] std::size_t log_count(const std::string& needle, std::size_t expected) const {
    std::size_t count = 0;
    (void)ds1928::test::wait_until([&] {
      const std::string text = log();
      count = 0;
      for (auto p = text.find(needle); p != std::string::npos; p = text.find(needle, p + 1))
        ++count;
      return count >= expected;
    });
    return count;
  }

  [[nodiscard]] uint64_t last_cycle() const { return ds1928_shm_last_cycle(&reader_.header()); }
  [[nodiscard]] const ShmReader& shm() const { return reader_; }
  [[nodiscard]] const std::string& socket_path() const { return socket_path_; }
  [[nodiscard]] const std::string& shm_name() const { return shm_name_; }
  [[nodiscard]] pid_t pid() const { return pid_; }

 private:
  std::string dir_;
  std::string shm_name_;
  std::string socket_path_;
  pid_t pid_ = -1;
  std::optional<int> exit_status_;
  ShmReader reader_;
};

// Raises the soft limit of open files to the hard limit (500 connections need more than 1024
// on some systems' defaults of 256).
inline void raise_fd_limit() {
  rlimit r{};
  if (getrlimit(RLIMIT_NOFILE, &r) == 0 && r.rlim_cur < r.rlim_max) {
    r.rlim_cur = r.rlim_max;
    setrlimit(RLIMIT_NOFILE, &r);
  }
}

}  // namespace ds1928::test
