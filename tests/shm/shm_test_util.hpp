// Helpers shared by the shared-memory tests: unique names, a child writer process.
#pragma once

#include <sched.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include "shm/publisher.hpp"

namespace ds1928::shm::test {

inline std::string unique_name(const char* what) {
  static int serial = 0;
  return "/ds1928d-test-" + std::string(what) + "-" + std::to_string(getpid()) + "-" +
         std::to_string(++serial);
}

inline ShmConfig config_for(const std::string& name) {
  ShmConfig c;
  c.name = name;
  return c;
}

// A sample whose every field follows from (cycle, axis): a torn copy mixes two cycles and
// fails both the check value and this relation.
inline AxisStatus status_for(uint64_t cycle, uint32_t axis) {
  AxisStatus s;
  const uint64_t v = cycle * 0x10001ull + axis;
  s.sample.position_raw = v << 16;
  s.sample.periods = static_cast<int64_t>(v);
  s.sample.position_sdc = static_cast<int32_t>(v << 16);
  s.sample.fraction = static_cast<uint16_t>(cycle * 8);
  s.sample.pos_time_raw = static_cast<uint32_t>(cycle);
  s.sample.pos_time_ns = static_cast<int64_t>(cycle * 1000);
  s.sample.time_source = TimeSource::NetTime;
  s.sample.pos_cycle = static_cast<int8_t>(cycle);
  s.sample.new_position = (cycle & 1) != 0;
  s.sample.error_info = static_cast<uint8_t>(cycle >> 3);
  s.sample.fresh = true;
  s.endat_error = static_cast<uint32_t>(cycle * 3);
  s.endat_warning = static_cast<uint32_t>(cycle * 5);
  s.validity = AxisValidity::Valid;
  return s;
}

inline bool consistent(const ds1928_axis_data& d, uint32_t axis) {
  const uint64_t v = d.cycle * 0x10001ull + axis;
  return d.check == ds1928_shm_check(&d) && d.position_raw == (v << 16) &&
         d.periods == static_cast<int64_t>(v) &&
         d.endat_error == static_cast<uint32_t>(d.cycle * 3) &&
         d.endat_warning == static_cast<uint32_t>(d.cycle * 5) &&
         d.pos_time_ns == static_cast<int64_t>(d.cycle * 1000);
}

inline int64_t now_ns() {
  return ds1928_shm_now_ns();
}

// Removes <name> and <name>.wait at scope exit, also when a REQUIRE ends the test early: a test
// that plays a dead daemon leaves its objects behind on purpose.
struct ObjectsRemover {
  std::string name;
  ~ObjectsRemover() {
    shm_unlink(name.c_str());
    shm_unlink((name + DS1928_SHM_WAIT_SUFFIX).c_str());
  }
};

// A second mapping of <name>.wait, to watch the readers' registrations from the test.
class ShmProbe {
 public:
  explicit ShmProbe(const std::string& name) {
    (void)ds1928_shm_reader_open(&reader_, name.c_str());
  }
  ~ShmProbe() { ds1928_shm_reader_close(&reader_); }
  ShmProbe(const ShmProbe&) = delete;
  ShmProbe& operator=(const ShmProbe&) = delete;
  bool is_open() const { return reader_.wait != nullptr; }
  // Readers registered in the slot of `factor` (0 while no slot has that factor).
  uint32_t waiters(uint32_t factor) const {
    for (const auto& slot : reader_.wait->slots)
      if (__atomic_load_n(&slot.factor, __ATOMIC_ACQUIRE) == factor)
        return __atomic_load_n(&slot.waiters, __ATOMIC_SEQ_CST);
    return 0;
  }

 private:
  ds1928_shm_reader reader_{};
};

// True when thread `tid` of this process is asleep (state S). A waiter registered in its slot
// and asleep sleeps in the futex: ds1928_shm_wait blocks nowhere else.
inline bool thread_sleeping(pid_t tid) {
  if (tid <= 0) return false;
  const std::string path = "/proc/self/task/" + std::to_string(tid) + "/stat";
  FILE* f = std::fopen(path.c_str(), "r");
  if (f == nullptr) return false;
  char buf[512];
  const size_t n = std::fread(buf, 1, sizeof(buf) - 1, f);
  std::fclose(f);
  buf[n] = 0;
  const char* close_paren = std::strrchr(buf, ')');  // the name may hold spaces and parens
  return close_paren != nullptr && close_paren[1] == ' ' && close_paren[2] == 'S';
}

// Forks a writer process: opens a Publisher on `name`, publishes `axes` axes every `period_ns`
// on an absolute timeline for `cycles` cycles (0: until killed; period 0: flat out), then
// either closes (clean stop) or stays alive without publishing for `linger_ms` (a hung daemon).
// Signals readiness through a pipe so that the parent maps a complete object.
struct WriterProcess {
  pid_t pid = -1;
  std::string name;
  // SCHED_FIFO priority of the writer, as the daemon's cycle thread has one (0: none; ignored
  // without the privilege). A real-time writer keeps its pace on a loaded machine and is not
  // descheduled in the middle of a record by ordinary threads.
  int fifo_priority = 0;

  void start(const std::string& name, uint32_t axes, int64_t period_ns, uint64_t cycles,
             bool close_at_end, int linger_ms = 0) {
    this->name = name;
    int fds[2];
    if (pipe(fds) != 0) return;
    const pid_t parent = getpid();
    pid = fork();
    if (pid == 0) {
      ::close(fds[0]);
      // A writer that publishes until killed must not outlive a test process that crashed.
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (getppid() != parent) _exit(3);
      prctl(PR_SET_TIMERSLACK, 1UL);
      if (fifo_priority > 0) {
        sched_param param{};
        param.sched_priority = fifo_priority;
        (void)sched_setscheduler(0, SCHED_FIFO, &param);
      }
      Publisher pub;
      char ok =
          pub.open(config_for(name), axes, static_cast<uint64_t>(period_ns > 0 ? period_ns : 1))
              ? 0
              : 1;
      (void)!write(fds[1], &ok, 1);
      ::close(fds[1]);
      if (!ok) _exit(2);
      std::vector<AxisStatus> st(axes);
      timespec next{};
      clock_gettime(CLOCK_MONOTONIC, &next);
      for (uint64_t c = 1; cycles == 0 || c <= cycles; ++c) {
        for (uint32_t a = 0; a < axes; ++a) st[a] = status_for(c, a);
        pub.publish(c, st);
        if (period_ns > 0) {
          next.tv_nsec += period_ns;
          while (next.tv_nsec >= 1'000'000'000) {
            next.tv_nsec -= 1'000'000'000;
            ++next.tv_sec;
          }
          clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
        }
      }
      if (close_at_end) {
        pub.close();
      } else {
        usleep(static_cast<useconds_t>(linger_ms) * 1000);
        _exit(0);  // no close: readers see publications stop (a dead daemon); the name leaks
      }
      _exit(0);
    }
    ::close(fds[1]);
    char ok = 0;
    if (read(fds[0], &ok, 1) != 1 || !ok) {
      stop();
    }
    ::close(fds[0]);
  }
  bool running() const { return pid > 0; }
  int join() {
    int status = 0;
    if (pid > 0) waitpid(pid, &status, 0);
    pid = -1;
    return status;
  }
  // Kills the writer; a killed writer cannot remove its objects, so this does (unless the test
  // wants the leftovers of a dead daemon).
  void stop(bool remove_objects = true) {
    const bool killed = pid > 0;
    if (killed) kill(pid, SIGKILL);
    join();
    if (killed && remove_objects) {
      shm_unlink(name.c_str());
      shm_unlink((name + DS1928_SHM_WAIT_SUFFIX).c_str());
    }
  }
  ~WriterProcess() { stop(); }
};

}  // namespace ds1928::shm::test
