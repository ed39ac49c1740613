// ds1928d stops cleanly on every signal that ends a daemon started by hand: SIGTERM and SIGINT
// (systemd, Ctrl-C), SIGHUP (the terminal of `make run` closed) and SIGPIPE (the log's pipe
// closed: `ds1928d … | head -1`). Clean: a log line naming the signal, exit 0, the shared memory
// removed and the control socket gone.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>

#include <catch2/catch.hpp>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>

#include "daemon/daemon_process.hpp"

using ds1928::test::DaemonProcess;

namespace {

void stops_cleanly(int signo, const std::string& name) {
  DaemonProcess d("sig" + name, "");
  REQUIRE(d.wait_ready());
  const std::string shm = d.shm_name();
  const std::string socket = d.socket_path();
  REQUIRE(std::filesystem::exists(socket));
  REQUIRE(::kill(d.pid(), signo) == 0);
  REQUIRE(ds1928::test::wait_until([&] { return !d.running(); }));
  INFO(d.log());
  const auto status = d.exit_status();
  REQUIRE(status.has_value());
  CHECK_FALSE(WIFSIGNALED(*status));
  REQUIRE(WIFEXITED(*status));
  CHECK(WEXITSTATUS(*status) == 0);
  CHECK(d.log_count("(SIG" + name + ") received: stopping", 1) == 1);
  CHECK(d.log_count("ds1928d stopping", 1) == 1);
  CHECK_FALSE(std::filesystem::exists(socket));
  // The reader the test held saw the daemon stop; the name is gone for new readers.
  CHECK(ds1928_shm_daemon_state(&d.shm().header()) == DS1928_DAEMON_STOPPED);
  errno = 0;
  const int fd = shm_open(shm.c_str(), O_RDONLY, 0);
  const int open_errno = errno;
  if (fd >= 0) ::close(fd);
  CHECK(fd < 0);
  CHECK(open_errno == ENOENT);
}

}  // namespace

TEST_CASE("SIGHUP stops the daemon like SIGTERM: log line, exit 0, shm and socket removed",
          "[daemon][signals]") {
  stops_cleanly(SIGHUP, "HUP");
}

TEST_CASE("SIGPIPE stops the daemon like SIGTERM: log line, exit 0, shm and socket removed",
          "[daemon][signals]") {
  stops_cleanly(SIGPIPE, "PIPE");
}

TEST_CASE("SIGTERM and SIGINT: the same clean stop", "[daemon][signals]") {
  stops_cleanly(SIGTERM, "TERM");
  stops_cleanly(SIGINT, "INT");
}
