// ds1928d: real-time master of X20DS1928 EnDat encoder modules.
#include <malloc.h>
#include <spdlog/spdlog.h>
#include <sys/un.h>

#include <CLI/CLI.hpp>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <string_view>
#include <vector>

#include "config/config_loader.hpp"
#include "core/rt_setup.hpp"
#include "daemon.hpp"
#include "host_checks.hpp"
#include "service/logging.hpp"

namespace {
constexpr std::size_t kThreadStackBytes = 1024 * 1024;
constexpr std::string_view kDefaultConfig = "/etc/ds1928d/ds1928d.yaml";

// The same rules as the configuration's shm.name and socket.path.
CLI::Validator shm_name_check() {
  return {[](const std::string& v) -> std::string {
            if (v.size() >= 2 && v.size() <= 255 && v.front() == '/' &&
                v.find('/', 1) == std::string::npos && v != "/." && v != "/..")
              return {};
            return "'" + v +
                   "' is not a shared-memory name: '/' followed by 1..254 characters "
                   "without '/'";
          },
          "NAME"};
}
CLI::Validator socket_path_check() {
  return {[](const std::string& v) -> std::string {
            if (!v.empty() && v.front() == '/' && v.back() != '/' &&
                v.size() < sizeof(sockaddr_un::sun_path))
              return {};
            return "'" + v + "' is not an absolute file path shorter than " +
                   std::to_string(sizeof(sockaddr_un::sun_path)) + " bytes";
          },
          "PATH"};
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ds1928d — real-time master of X20DS1928 EnDat encoder modules"};
  std::string config_path = std::string(kDefaultConfig);
  std::string check_path;
  bool print_config = false;
  bool no_host_checks = false;
  app.add_option("-c,--config", config_path,
                 "configuration file (YAML); default " + std::string(kDefaultConfig));
  app.add_option("--check-config", check_path,
                 "validate FILE (and this host: interfaces, groups) without touching the bus; "
                 "exit 0 when valid, 2 otherwise");
  app.add_flag("--print-config", print_config,
               "print the effective configuration (every default filled in) of --check-config "
               "FILE or of -c FILE, and exit: never starts the bus");
  app.add_flag("--no-host-checks", no_host_checks,
               "with --check-config/--print-config: check the file alone, not this host (a file "
               "meant for another machine)");
  std::string shm_name;
  std::string socket_path;
  app.add_option("--shm-name", shm_name,
                 "publish under this shared memory name instead of shm.name (e.g. /ds1928d-line2)")
      ->check(shm_name_check());
  app.add_option("--socket", socket_path,
                 "listen on this control socket instead of socket.path (an absolute path)")
      ->check(socket_path_check());
  app.set_version_flag("--version", "ds1928d " PROJECT_VERSION);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }

  const bool check_only = !check_path.empty() || print_config;
  const std::string& path = check_path.empty() ? config_path : check_path;
  auto loaded = ds1928::load_config(path);
  if (!loaded) {
    std::fprintf(stderr, "%s", loaded.error_report().c_str());
    std::fprintf(stderr, "%s: %zu error(s)\n", path.c_str(), loaded.errors().size());
    return 2;
  }
  auto config = std::move(loaded).config();
  // The template unit ds1928d@NAME.service gives each instance its own shared memory and socket
  // from the instance name, so that NAME.yaml need not repeat them.
  if (!shm_name.empty()) config.shm.name = shm_name;
  if (!socket_path.empty()) config.socket.path = socket_path;
  if (check_only) {
    const std::vector<std::string> problems =
        no_host_checks ? std::vector<std::string>{} : ds1928::host_problems(config);
    for (const std::string& p : problems) std::fprintf(stderr, "%s: %s\n", path.c_str(), p.c_str());
    if (!problems.empty()) {
      std::fprintf(stderr, "%s: %zu error(s) on this host\n", path.c_str(), problems.size());
      return 2;
    }
    if (print_config) std::cout << ds1928::dump_config(config) << std::flush;
    // With --print-config stdout is the YAML alone (it loads back); the verdict goes to stderr.
    std::FILE* verdict = print_config ? stderr : stdout;
    std::fprintf(verdict, "%s: ok (bus %s, %zu axis(es), cycle %u µs)\n", path.c_str(),
                 std::string(ds1928::to_string(config.bus)).c_str(), config.axes.size(),
                 config.cycle.period_us);
    std::fprintf(verdict, "%s: %s\n", path.c_str(),
                 no_host_checks ? "this host not checked (--no-host-checks)"
                                : ds1928::checks_left_to_start(config).c_str());
    return 0;
  }
  // mlockall locks every thread's whole stack in RAM: 1 MiB usable each (the cycle thread
  // pre-faults 256 KiB of it) instead of glibc's default of RLIMIT_STACK, usually 8 MiB. Before the
  // first thread (the logger's) starts.
  const ds1928::rt::SetupStep stack = ds1928::rt::limit_default_thread_stack(kThreadStackBytes);
  // Under mlockall a heap page stays resident until malloc gives it back. Blocks from 64 KiB
  // (a client's reply buffer, a capture's output) get their own mapping, returned at free()
  // (glibc's threshold would otherwise climb to 32 MiB after the first such free), and free
  // space above 128 KiB at the top of the heap is returned at once; Daemon's tick trims the
  // rest once a second. One malloc arena per thread at most 2: each arena keeps its own free
  // pages.
  mallopt(M_MMAP_THRESHOLD, 64 * 1024);
  mallopt(M_TRIM_THRESHOLD, 128 * 1024);
  mallopt(M_ARENA_MAX, 2);
  // Until the Daemon handles SIGPIPE as a stop request, a log line into a pipe whose reader left
  // must not kill the process before it can clean up.
  std::signal(SIGPIPE, SIG_IGN);
  const auto level =
      ds1928::control::parse_log_level(config.log_level).value_or(spdlog::level::info);
  ds1928::control::setup_logging(level, ds1928::control::detect_log_sink());
  if (!stack.ok())
    spdlog::warn("thread stacks stay at the system default ({}): each is locked in RAM whole",
                 ds1928::rt::errno_text(stack.error));
  int rc = 0;
  {
    ds1928::Daemon daemon(std::move(config));
    rc = daemon.run();
  }
  // The Daemon's signal handlers are gone: the log's last lines into a pipe whose reader left
  // (`ds1928d | head -1`) must not end the exit with SIGPIPE.
  std::signal(SIGPIPE, SIG_IGN);
  ds1928::control::shutdown_logging();
  return rc;
}
