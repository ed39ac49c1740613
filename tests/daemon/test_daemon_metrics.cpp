// The ds1928d process' OpenMetrics endpoint: a scrape taken while the daemon cycles passes
// `promtool check metrics` (Debian package prometheus) in the text format, OpenMetrics is served
// on request; and the endpoint survives abuse — garbage, oversized headers, 1000 connections at
// once, clients that never finish their request or never read — with the daemon cycling
// throughout, its memory bounded, and the endpoint answering afterwards.
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "../control/control_test_util.hpp"
#include "daemon_process.hpp"

using namespace ds1928;
using control::test::LineClient;
using json = nlohmann::json;
using test::DaemonProcess;

namespace {

// Timeouts short enough that the slow clients below are cut within the test.
const std::string kMetricsYaml = "metrics: {listen: '127.0.0.1:0', timeout_ms: 500}\n";

int connect_tcp(uint16_t port, bool blocking = true) {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | (blocking ? 0 : SOCK_NONBLOCK), 0);
  if (fd < 0) return -1;
  timeval tv{20, 0};  // a bound against a hang, never what is measured
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof(tv));
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0 && errno != EINPROGRESS) {
    ::close(fd);
    return -1;
  }
  return fd;
}

bool send_all(int fd, std::string_view bytes) {
  while (!bytes.empty()) {
    const ssize_t n = ::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    bytes.remove_prefix(static_cast<std::size_t>(n));
  }
  return true;
}

// Everything until the server closes (or the 20 s receive bound).
std::string read_all(int fd) {
  std::string out;
  char buf[65536];
  for (;;) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    out.append(buf, static_cast<std::size_t>(n));
  }
  return out;
}

std::string http_exchange(uint16_t port, std::string_view request) {
  const int fd = connect_tcp(port);
  if (fd < 0) return {};
  // A refused request may be answered before it is sent whole: read the answer either way.
  (void)send_all(fd, request);
  std::string reply = read_all(fd);
  ::close(fd);
  return reply;
}

struct Response {
  int status = 0;
  std::string headers;
  std::string body;
};

Response parse_response(const std::string& raw) {
  Response r;
  const auto end = raw.find("\r\n\r\n");
  if (raw.rfind("HTTP/1.1 ", 0) != 0 || end == std::string::npos) return r;
  r.status = std::atoi(raw.c_str() + 9);
  r.headers = raw.substr(0, end + 2);
  r.body = raw.substr(end + 4);
  return r;
}

Response scrape(uint16_t port, std::string_view accept = "*/*") {
  return parse_response(http_exchange(port, "GET /metrics HTTP/1.1\r\nHost: localhost\r\nAccept: " +
                                                std::string(accept) + "\r\n\r\n"));
}

// The endpoint's port, from `status` (daemon.metrics "127.0.0.1:PORT").
uint16_t metrics_port(const std::string& socket_path) {
  LineClient c(socket_path, 10000);
  if (!c.send_raw("{\"cmd\":\"status\"}\n")) return 0;
  const auto line = c.read_line();
  if (!line) return 0;
  const json j = json::parse(*line, nullptr, false);
  const std::string at = j.value("/daemon/metrics"_json_pointer, std::string());
  const auto colon = at.rfind(':');
  return colon == std::string::npos ? 0 : static_cast<uint16_t>(std::stoi(at.substr(colon + 1)));
}

// A sample's value from the text format ("name{labels} value"); -1 when absent.
double value_of(const std::string& body, const std::string& series) {
  const auto at = body.find("\n" + series + " ");
  if (at == std::string::npos) return -1;
  return std::strtod(body.c_str() + at + series.size() + 2, nullptr);
}

struct Run {
  int status = -1;
  std::string output;
};
Run run(const std::string& command) {
  Run r;
  FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  if (!p) return r;
  char buf[4096];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  const int st = ::pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

}  // namespace

TEST_CASE("A scrape while the daemon cycles passes promtool check metrics", "[daemon][metrics]") {
  DaemonProcess d("metrics", "", kMetricsYaml);
  REQUIRE(d.wait_ready());
  const uint16_t port = metrics_port(d.socket_path());
  REQUIRE(port != 0);

  const Response text = scrape(port);
  INFO(text.headers);
  REQUIRE(text.status == 200);
  CHECK_THAT(text.headers,
             Catch::Contains("Content-Type: text/plain; version=0.0.4; charset=utf-8\r\n"));
  CHECK_THAT(text.headers,
             Catch::Contains("Content-Length: " + std::to_string(text.body.size()) + "\r\n"));
  const double cycles = value_of(text.body, "ds1928_cycles_total");
  CHECK(cycles > 0);
  for (const char* family :
       {"# TYPE ds1928_cycle_wakeup_lateness_seconds histogram",
        "# TYPE ds1928_cycle_overruns_total counter",
        "# TYPE ds1928_axis_publications_total counter",
        "# TYPE ds1928_endat_command_latency_seconds histogram",
        "# TYPE ds1928_socket_clients gauge",
        "ds1928_bus_state{bus=\"simulated\",state=\"operational\"} 1",
        "ds1928_axis_publications_total{axis=\"0\",name=\"x\",validity=\"valid\"}"})
    CHECK_THAT(text.body, Catch::Contains(family));
  // The per-axis state gauge: both axes valid now, exactly one state series 1 per axis.
  CHECK_THAT(text.body, Catch::Contains("# TYPE ds1928_axis_state gauge"));
  for (const char* axis : {"axis=\"0\",name=\"x\"", "axis=\"1\",name=\"y\""}) {
    double ones = 0;
    for (const char* state : {"valid", "stale", "bus_down", "module_error"}) {
      const double v = value_of(
          text.body, std::string("ds1928_axis_state{") + axis + ",state=\"" + state + "\"}");
      CHECK((v == 0 || v == 1));
      ones += v;
      if (std::string_view(state) == "valid") CHECK(v == 1);
    }
    CHECK(ones == 1);
  }
  // Every wake-up is in the histogram: +Inf bucket = count.
  CHECK(value_of(text.body, "ds1928_cycle_wakeup_lateness_seconds_bucket{le=\"+Inf\"}") ==
        value_of(text.body, "ds1928_cycle_wakeup_lateness_seconds_count"));

  // promtool (Debian package prometheus, Makefile TEST_DEPS) parses and lints the scrape.
  const std::string file = "/tmp/ds1928-metrics-" + std::to_string(::getpid()) + ".txt";
  {
    std::ofstream f(file);
    f << text.body;
  }
  const Run promtool = run("promtool check metrics < " + file);
  std::remove(file.c_str());
  INFO(promtool.output);
  REQUIRE(promtool.status != 127);  // not installed: `make deps-test`
  CHECK(promtool.status == 0);
  CHECK(promtool.output.empty());  // no lint complaint either

  // OpenMetrics on request, ending in # EOF.
  const Response om =
      scrape(port, "application/openmetrics-text;version=1.0.0,text/plain;version=0.0.4;q=0.5");
  REQUIRE(om.status == 200);
  CHECK_THAT(om.headers, Catch::Contains("Content-Type: application/openmetrics-text; "
                                         "version=1.0.0; charset=utf-8\r\n"));
  CHECK_THAT(om.body, Catch::Contains("# TYPE ds1928_cycles counter\nds1928_cycles_total "));
  CHECK_THAT(om.body, Catch::Contains("# UNIT ds1928_cycle_wakeup_lateness_seconds seconds\n"));
  CHECK_THAT(om.body, Catch::EndsWith("\n# EOF\n"));

  // The figures move: the daemon cycles between scrapes.
  REQUIRE(test::wait_until(
      [&] { return value_of(scrape(port).body, "ds1928_cycles_total") > cycles; }));

  // HEAD: the headers of GET, no body.
  const Response head = parse_response(http_exchange(port, "HEAD /metrics HTTP/1.0\r\n\r\n"));
  CHECK(head.status == 200);
  CHECK(head.body.empty());
}

TEST_CASE("The metrics endpoint refuses bad requests with a status and a reason",
          "[daemon][metrics]") {
  DaemonProcess d("metrics-bad", "", kMetricsYaml);
  REQUIRE(d.wait_ready());
  const uint16_t port = metrics_port(d.socket_path());
  REQUIRE(port != 0);
  const auto status_of = [&](std::string_view request) {
    return parse_response(http_exchange(port, request));
  };
  auto r = status_of("GET / HTTP/1.1\r\nHost: h\r\n\r\n");
  CHECK(r.status == 404);
  CHECK_THAT(r.body, Catch::Contains("the only resource is /metrics"));
  r = status_of("POST /metrics HTTP/1.1\r\nHost: h\r\nContent-Length: 0\r\n\r\n");
  CHECK(r.status == 405);
  CHECK_THAT(r.headers, Catch::Contains("Allow: GET, HEAD\r\n"));
  CHECK(status_of("GET /metrics HTTP/1.1\r\nHost: h\r\nContent-Length: 3\r\n\r\nabc").status ==
        413);
  CHECK(status_of("GET /metrics HTTP/1.1\r\nHost: h\r\nX: " + std::string(9000, 'a') + "\r\n\r\n")
            .status == 431);
  CHECK(status_of("\x16\x03\x01\x00\xa5\x01\x00\x00").status == 400);  // a TLS ClientHello
}

TEST_CASE("The metrics endpoint survives abuse, the daemon cycles on, memory stays bounded",
          "[daemon][metrics][hostile]") {
  test::raise_fd_limit();
  DaemonProcess d("metrics-abuse", "", kMetricsYaml);
  REQUIRE(d.wait_ready());
  const uint16_t port = metrics_port(d.socket_path());
  REQUIRE(port != 0);
  REQUIRE(scrape(port).status == 200);  // warm: the first scrape's allocations are not growth
  const long rss_before = d.vm_kb("VmRSS");
  const uint64_t cycle_before = d.last_cycle();

  // 1. Garbage: random bytes, 300 connections one after the other.
  std::mt19937 rng(20);
  int garbage_answered = 0;
  for (int i = 0; i < 300; ++i) {
    std::string junk(1 + rng() % 2000, '\0');
    for (char& c : junk) c = static_cast<char>(rng());
    const Response r = parse_response(http_exchange(port, junk));
    if (r.status >= 400 && r.status < 500) ++garbage_answered;
  }
  CHECK(garbage_answered >= 250);  // the rest: junk that is a valid start, cut at the timeout

  // 2. Oversized headers: 50 × 64 KiB offered, 431 after 8 KiB.
  int refused_431 = 0;
  for (int i = 0; i < 50; ++i) {
    const Response r = parse_response(http_exchange(
        port,
        "GET /metrics HTTP/1.1\r\nHost: h\r\nX-Big: " + std::string(65536, 'b') + "\r\n\r\n"));
    if (r.status == 431) ++refused_431;
  }
  CHECK(refused_431 == 50);

  // 3. 1000 connections at once, each sending half a request and then nothing (slowloris):
  // 64 are held until the read timeout, the others are told 503 at once.
  std::vector<int> fds;
  for (int i = 0; i < 1000; ++i) {
    const int fd = connect_tcp(port);
    if (fd < 0) break;
    (void)send_all(fd, "GET /metrics HTTP/1.1\r\nHost: h\r\n");
    fds.push_back(fd);
  }
  CHECK(fds.size() == 1000);
  int answered_503 = 0, cut = 0;
  for (int fd : fds) {
    const Response r = parse_response(read_all(fd));
    if (r.status == 503)
      ++answered_503;
    else if (r.status == 0)
      ++cut;  // held, then closed at the read timeout without a word
    ::close(fd);
  }
  fds.clear();
  // Every connection was told 503 or closed: none hangs. (Which ones were held depends on
  // timing: a held one's timeout frees its slot for a later one; the peak is checked below.)
  CHECK(answered_503 + cut == 1000);
  CHECK(cut >= 64);
  CHECK(answered_503 >= 500);

  // 4. Slow readers: 64 connections ask for the metrics and never read the answer, with a small
  // receive buffer; they are cut after the write timeout or when their buffers took it all.
  for (int i = 0; i < 64; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    const int small = 1024;
    setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0)
      (void)send_all(fd, "GET /metrics HTTP/1.1\r\nHost: h\r\n\r\n");
    fds.push_back(fd);
  }
  // The endpoint answers others meanwhile: a new connection gets 200 once slots free (the slow
  // readers hold them at most the write timeout).
  Response after;
  CHECK(test::wait_until([&] {
    after = scrape(port);
    return after.status == 200;
  }));
  for (int fd : fds) ::close(fd);

  // The daemon cycled throughout, and its memory did not grow with the abuse.
  REQUIRE(d.running());
  const uint64_t cycle_after = d.last_cycle();
  CHECK(cycle_after > cycle_before);
  const long rss_after = d.vm_kb("VmRSS");
  std::fprintf(stderr,
               "metrics abuse: garbage 300 (%d answered 4xx), oversized 50 (%d × 431), 1000 "
               "connections (%d × 503, %d held and cut), 64 slow readers; cycles %llu -> %llu; "
               "VmRSS %ld kB -> %ld kB, VmHWM %ld kB; endpoint peak %.0f connections\n",
               garbage_answered, refused_431, answered_503, cut,
               static_cast<unsigned long long>(cycle_before),
               static_cast<unsigned long long>(cycle_after), rss_before, rss_after,
               d.vm_kb("VmHWM"), value_of(after.body, "ds1928_http_connections_peak"));
  CHECK(rss_after - rss_before < test::memory_bound_kb(8 * 1024));
  // The endpoint counted what it refused and cut.
  CHECK(value_of(after.body, "ds1928_http_connections_total{result=\"refused\"}") >= answered_503);
  CHECK(value_of(after.body, "ds1928_http_timeouts_total{stage=\"read\"}") >= 64);
  // Never more than metrics.max_connections (64) open at once, whatever came.
  const double peak = value_of(after.body, "ds1928_http_connections_peak");
  CHECK(peak >= 1);
  CHECK(peak <= 64);
}

TEST_CASE("metrics.listen: off opens no endpoint", "[daemon][metrics]") {
  DaemonProcess d("metrics-off", "", "metrics: {listen: 'off'}\n");
  REQUIRE(d.wait_ready());
  LineClient c(d.socket_path(), 10000);
  REQUIRE(c.send_raw("{\"cmd\":\"status\"}\n"));
  const auto line = c.read_line();
  REQUIRE(line);
  CHECK(json::parse(*line).value("/daemon/metrics"_json_pointer, std::string()) == "off");
}
