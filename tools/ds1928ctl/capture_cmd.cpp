// `ds1928ctl capture -w FILE [--duration S | --count N] [--format pcapng|candump]` and
// `ds1928ctl capture-stop`: record what the daemon's bus driver sends and receives (capture in
// docs/socket-protocol.md). The daemon streams the file as base64 "capture_data" lines and ends
// with the reply; this writes the bytes to FILE (or stdout for "-", e.g. into `wireshark -k -i -`)
// and prints the summary (to stderr when the data goes to stdout). Ctrl-C asks the daemon to end
// the capture (capture-stop on a second connection), so the file still gets its statistics.
#include <fcntl.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "capture/base64.hpp"
#include "client.hpp"
#include "commands.hpp"

namespace ds1928::ctl {
namespace {

volatile std::sig_atomic_t g_interrupted = 0;
void on_interrupt(int) {
  g_interrupted = 1;
}

struct CaptureArgs {
  std::string output;
  double duration_s = 0;
  uint64_t count = 0;
  std::string format = "pcapng";
};

bool write_all(int fd, const uint8_t* data, std::size_t size) {
  while (size > 0) {
    const ssize_t n = ::write(fd, data, size);
    if (n < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    data += n;
    size -= static_cast<std::size_t>(n);
  }
  return true;
}

void print_summary(std::ostream& out, const nlohmann::json& c) {
  out << "capture ended (" << c.value("reason", std::string("?"))
      << "): " << c.value("frames", uint64_t{0}) << " frames, " << c.value("bytes", uint64_t{0})
      << " bytes, " << c.value("format", std::string()) << "\n";
  for (const auto& i : c.value("interfaces", nlohmann::json::array()))
    out << "  " << i.value("name", std::string()) << " (" << i.value("description", std::string())
        << "): " << i.value("frames", uint64_t{0}) << " frames in the window, "
        << i.value("captured", uint64_t{0}) << " captured (tx " << i.value("tx", uint64_t{0})
        << ", rx " << i.value("rx", uint64_t{0}) << "), " << i.value("dropped", uint64_t{0})
        << " dropped\n";
}

// Whether FILE can be written, asked before the capture starts (the file itself is created
// with the first data, so that a capture the daemon refuses leaves no empty file behind).
std::string cannot_write(const std::string& path) {
  if (::access(path.c_str(), F_OK) == 0) {
    const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
    if (fd < 0) return std::strerror(errno);
    ::close(fd);
    return {};
  }
  const auto slash = path.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "."
                          : slash == 0               ? "/"
                                                     : path.substr(0, slash);
  if (::access(dir.c_str(), W_OK | X_OK) != 0) return dir + ": " + std::strerror(errno);
  return {};
}

int run_capture(const Context& ctx, const CaptureArgs& a) {
  const bool to_stdout = a.output == "-";
  int out_fd = to_stdout ? STDOUT_FILENO : -1;
  if (!to_stdout) {
    if (const auto why = cannot_write(a.output); !why.empty()) {
      std::cerr << "ds1928ctl: cannot write " << a.output << ": " << why << "\n";
      return kUsage;
    }
  }
  const std::unique_ptr<int, void (*)(int*)> closer(&out_fd, [](int* fd) {
    if (*fd >= 0 && *fd != STDOUT_FILENO) ::close(*fd);
  });
  std::ostream& info = to_stdout ? std::cerr : std::cout;

  nlohmann::json request{{"cmd", "capture"}, {"format", a.format}};
  if (a.duration_s > 0) request["duration_ms"] = static_cast<uint64_t>(a.duration_s * 1000 + 0.5);
  if (a.count > 0) request["count"] = a.count;

  std::signal(SIGPIPE, SIG_IGN);  // a reader that goes away (wireshark closed): EPIPE, then exit
  struct sigaction sa {};
  sa.sa_handler = on_interrupt;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  bool stop_sent = false;
  StreamOutcome o = stream_request(
      ctx, request,
      [&](const nlohmann::json& line) {
        const auto it = line.find("capture_data");
        if (it == line.end() || !it->is_string()) return true;  // unknown line kinds: skipped
        const auto bytes = capture::base64_decode(it->get_ref<const std::string&>());
        if (!bytes) throw std::runtime_error("capture_data is not base64");
        if (out_fd < 0) {
          out_fd = ::open(a.output.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0640);
          if (out_fd < 0) {
            std::cerr << "ds1928ctl: cannot write " << a.output << ": " << std::strerror(errno)
                      << "\n";
            return false;  // closing the connection ends the capture in the daemon
          }
        }
        if (!write_all(out_fd, bytes->data(), bytes->size())) {
          std::cerr << "ds1928ctl: writing " << (to_stdout ? "stdout" : a.output) << ": "
                    << std::strerror(errno) << "\n";
          return false;  // closing the connection ends the capture in the daemon
        }
        return true;
      },
      [&] {
        // Ctrl-C: ask the daemon to end the capture; its final data and reply still arrive.
        if (g_interrupted && !stop_sent) {
          stop_sent = true;
          const Outcome s = send_request(ctx, {{"cmd", "capture-stop"}});
          if (s.exit != kOk) std::cerr << "ds1928ctl: capture-stop: " << s.problem << "\n";
        }
      });
  if (o.exit == kOk && out_fd < 0) {  // a capture that ended before any data: still a file
    out_fd = ::open(a.output.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0640);
    if (out_fd < 0) std::cerr << "ds1928ctl: cannot write " << a.output << "\n";
  }
  if (o.exit == kOk && ctx.json) {
    info << o.reply.dump() << std::endl;
  } else if (o.exit == kOk) {
    print_summary(info, o.reply.value("capture", nlohmann::json::object()));
  } else {
    if (o.exit == kDaemonError && ctx.json) info << o.reply.dump() << std::endl;
    std::cerr << "ds1928ctl: " << (o.exit == kDaemonError ? "error: " : "") << o.problem << "\n";
  }
  return o.exit;
}

}  // namespace

void add_capture_commands(CLI::App& app, Context& ctx) {
  auto args = std::make_shared<CaptureArgs>();
  auto* cap = app.add_subcommand(
      "capture",
      "Record the frames the daemon's bus driver sends and receives (pcapng or candump log)");
  cap->add_option("-w,--write", args->output, "Output file, '-' for stdout (wireshark -k -i -)")
      ->required();
  auto* dur = cap->add_option("--duration", args->duration_s, "Stop after S seconds")
                  ->check(CLI::PositiveNumber);
  auto* cnt = cap->add_option("--count", args->count, "Stop after N frames")
                  ->check(CLI::Range(uint64_t{1}, UINT64_MAX));
  dur->excludes(cnt);
  cap->add_option("--format", args->format, "pcapng (default) or candump (CAN-I/O only)")
      ->check(CLI::IsMember({"pcapng", "candump"}))
      ->capture_default_str();
  cap->callback([&ctx, args] { ctx.action = [&ctx, args] { return run_capture(ctx, *args); }; });

  auto* stop = app.add_subcommand("capture-stop",
                                  "End the running capture (its client gets the "
                                  "rest of the file)");
  stop->callback([&ctx] {
    ctx.action = [&ctx] {
      return request_and_print(ctx, {{"cmd", "capture-stop"}}, [](const nlohmann::json& r) {
        const auto& s = r.at("stopped");
        std::cout << "capture of pid " << s.value("pid", 0) << " stopped after "
                  << s.value("frames", uint64_t{0}) << " frames\n";
      });
    };
  });
}

}  // namespace ds1928::ctl
