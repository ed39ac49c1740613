// The ds1928d process against hostile clients: every kind of malformed request (one of them,
// a 400-digit number, used to abort the daemon), clients that never read their replies (the
// daemon's peak RSS must stay within the per-client reply bound), 10^5 garbage requests and 500
// connections at once — while the shared memory shows the cycle going on.
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <cstring>
#include <latch>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "../control/control_test_util.hpp"
#include "daemon_process.hpp"

using namespace ds1928;
using json = nlohmann::json;
using control::test::error_code_of;
using control::test::error_message_of;
using control::test::LineClient;
using test::DaemonProcess;

namespace {

json parse(const std::optional<std::string>& line) {
  return line ? json::parse(*line, nullptr, false) : json();
}

// A line sent on its own connection (some bad lines end it); the reply.
json one_shot(const std::string& path, const std::string& line) {
  LineClient c(path, 10000);
  if (!c.send_raw(line + "\n")) return json();
  return parse(c.read_line());
}

// Watches the shm from its own thread: every publication is awaited with a 2 s deadline (the
// period is 1 ms); a timeout means the cycle stopped publishing while the clients ran.
class CycleWatch {
 public:
  explicit CycleWatch(const std::string& shm_name) {
    if (reader_.open(shm_name)) return;
    first_ = ds1928_shm_last_cycle(&reader_.header());
    thread_ = std::thread([this] { run(); });
  }
  ~CycleWatch() { stop(); }
  void stop() {
    done_ = true;
    if (thread_.joinable()) thread_.join();
  }
  [[nodiscard]] bool opened() const { return reader_.is_open(); }
  [[nodiscard]] uint64_t advanced() const { return last_ - first_; }
  [[nodiscard]] uint64_t stalls() const { return stalls_; }
  [[nodiscard]] int64_t max_gap_ns() const { return max_gap_ns_; }

 private:
  void run() {
    uint64_t seen = reader_.wait_start();
    int64_t previous = ds1928_shm_last_publish_ns(&reader_.header());
    while (!done_) {
      std::error_code ec;
      const auto r = reader_.wait(seen, 1, ds1928_shm_now_ns() + 2'000'000'000, ec);
      if (r != ShmWait::Published) {
        ++stalls_;
        if (r == ShmWait::Stopped || ec) return;
        continue;
      }
      last_ = seen;
      const int64_t at = ds1928_shm_last_publish_ns(&reader_.header());
      max_gap_ns_ = std::max(max_gap_ns_, at - previous);
      previous = at;
    }
  }

  ShmReader reader_;
  std::thread thread_;
  std::atomic<bool> done_{false};
  uint64_t first_ = 0;
  uint64_t last_ = 0;
  uint64_t stalls_ = 0;
  int64_t max_gap_ns_ = 0;
};

// The argument fields of each command (docs/socket-protocol.md) with a valid value each: a
// request built from these is well-formed, so that one wrong field is the only fault.
const std::map<std::string, json>& command_args() {
  static const std::map<std::string, json> args{
      {"status", json::object()},
      {"axes", json::object()},
      {"stats", json::object()},
      {"stats-reset", json::object()},
      {"ack-errors", {{"axis", 0}, {"bits", 1}}},
      {"pl-pres", {{"node", 1}}},
      {"pl-preq-set", {{"node", 1}, {"offset", 0}, {"hex", "00"}}},
      {"endat-reset", {{"axis", 0}}},
      {"endat-ack", {{"axis", 0}}},
      {"endat-read-param", {{"axis", 0}, {"mrs", 0xA1}, {"param", 0}}},
      {"endat-write-param", {{"axis", 0}, {"mrs", 0xA1}, {"param", 0}, {"value", 0}}},
      {"endat-read-block", {{"axis", 0}, {"mrs", 0xA1}, {"block", 0}, {"param", 0}}},
      {"endat-write-block", {{"axis", 0}, {"mrs", 0xA1}, {"block", 0}, {"param", 0}, {"value", 0}}},
      {"endat-read-info", {{"axis", 0}, {"word", 1}, {"mrs", 0x40}}},
      {"endat-dump", {{"axis", 0}, {"mrs", 0xA1}, {"count", 1}}},
      {"endat-ident", {{"axis", 0}, {"refresh", false}}},
      {"endat-rescan", {{"axis", 0}}},
      {"endat-ack-register", {{"axis", 0}}},
  };
  return args;
}

// Wrong for every argument field, as JSON text (some are not representable as a json value).
const std::vector<std::string>& wrong_values() {
  static const std::vector<std::string> values{
      "-1",
      "1.5",
      "\"zero\"",
      "\"\"",
      "[]",
      "{}",
      "null",
      "true",
      "1" + std::string(400, '0'),  // overflows a double: the parser throws out_of_range
      "1e400",                      // the same in exponent form
      "18446744073709551616",       // 2^64
      "99999",                      // out of range for every field
      std::string(65, '[') + std::string(65, ']'),  // deeper than the 64 levels accepted
  };
  return values;
}

std::string request_text(const std::string& cmd, const json& args, const std::string& field,
                         const std::string& value) {
  std::string s = "{\"cmd\":\"" + cmd + "\"";
  for (const auto& [k, v] : args.items())
    if (k != field) s += ",\"" + k + "\":" + v.dump();
  return s + ",\"" + field + "\":" + value + "}";
}

// Line `i` of the garbage storm: each kind of malformed request in turn, never a valid one.
std::string garbage(std::mt19937_64& rng, uint64_t i) {
  auto pick = [&](std::size_t n) { return static_cast<std::size_t>(rng() % n); };
  switch (i % 8) {
    case 0: {  // random bytes (no newline; the first one visible so the line is not blank)
      std::string s(1 + pick(120), ' ');
      for (auto& c : s) {
        do c = static_cast<char>(rng());
        while (c == '\n');
      }
      s[0] = static_cast<char>('!' + pick(90));
      return s;
    }
    case 1:
      // beyond DBL_MAX (1.8e308)
      return "{\"cmd\":\"status\",\"id\":1" + std::string(310 + pick(200), '0') + "}";
    case 2: {
      const std::size_t depth = 65 + pick(500);
      return "{\"cmd\":\"status\",\"id\":" + std::string(depth, '[') + std::string(depth, ']') +
             "}";
    }
    case 3: {  // bytes 0x80..0xFF in a string: mostly ill-formed UTF-8
      std::string s = "{\"cmd\":\"";
      for (std::size_t k = 0, n = 1 + pick(8); k < n; ++k)
        s += static_cast<char>(0x80 + pick(0x80));
      return s + "\"}";
    }
    case 4:
      return std::string("{\"cmd\":\"sta") + '\0' + "tus\"}";
    case 5: {
      static const char* wrong[] = {"-1", "1.5", "\"0\"", "[]", "{}", "null", "true", "1e400"};
      return std::string("{\"cmd\":\"ack-errors\",\"axis\":") + wrong[pick(8)] + ",\"bits\":1}";
    }
    case 6: {
      static const char* wrong[] = {"5", "null", "[\"status\"]", "{}", "\"x\\u0000y\"", "\"\""};
      return std::string("{\"cmd\":") + wrong[pick(6)] + "}";
    }
    default:
      return "{\"cmd\":\"" + std::string(100 + pick(3000), 'z') + "\"}";
  }
}

}  // namespace

TEST_CASE("malformed requests of every kind get an error reply and the daemon keeps cycling",
          "[daemon][socket][hostile]") {
  DaemonProcess d("bad", "max_request_bytes: 4096");
  REQUIRE(d.wait_ready());
  const std::string& path = d.socket_path();

  // The request that aborted ds1928d: a number beyond a double.
  const json big_id = one_shot(path, "{\"cmd\":\"status\",\"id\":1" + std::string(400, '0') + "}");
  CHECK(error_code_of(big_id) == "bad_json");
  CHECK_THAT(error_message_of(big_id), Catch::Contains("number overflow"));
  CHECK(error_message_of(big_id).size() < 300);  // a bounded prefix of the number
  REQUIRE(d.running());

  struct Case {
    const char* what;
    std::string line;
    const char* code;
    const char* message;
  };
  const std::vector<Case> cases{
      {"exponent overflow", "{\"cmd\":\"ack-errors\",\"axis\":1e400,\"bits\":1}", "bad_json",
       "number overflow"},
      {"deep nesting", "{\"cmd\":\"status\",\"id\":" + std::string(3000, '[') + "}", "bad_json",
       "nested deeper than 64"},
      {"deep nesting, well-formed",
       "{\"cmd\":\"status\",\"x\":" + std::string(200, '[') + std::string(200, ']') + "}",
       "bad_json", "nested deeper than 64"},
      {"brackets in a string do not nest", "{\"cmd\":\"" + std::string(200, '[') + "\"}",
       "unknown_command", "unknown command"},
      {"ill-formed UTF-8", "{\"cmd\":\"st\xff\xfe\"}", "bad_json", "UTF-8"},
      {"NUL byte", std::string("{\"cmd\":\"st\0atus\"}", 16), "bad_json", "NUL"},
      {"escaped NUL", "{\"cmd\":\"st\\u0000atus\"}", "unknown_command", "unknown command"},
      {"not an object", "[1,2,3]", "bad_json", "must be a JSON object"},
      {"cmd of the wrong type", "{\"cmd\":[\"status\"]}", "bad_argument", "'cmd'"},
      {"huge unknown command", "{\"cmd\":\"" + std::string(4000, 'q') + "\"}", "unknown_command",
       "(4000 bytes)"},
      {"oversized line", std::string(10000, 'x'), "request_too_large", "4096 bytes"},
  };
  for (const auto& c : cases) {
    INFO(c.what);
    const json r = one_shot(path, c.line);
    CHECK(error_code_of(r) == c.code);
    CHECK_THAT(error_message_of(r), Catch::Contains(c.message));
    REQUIRE(d.running());
  }

  // A request split over many writes, one byte each, is one request.
  {
    LineClient c(path, 10000);
    const std::string line = "{\"cmd\":\"status\",\"id\":42}\n";
    for (char ch : line) REQUIRE(c.send_raw(std::string(1, ch)));
    const json r = parse(c.read_line());
    CHECK(r.value("ok", false));
    CHECK(r.value("id", 0) == 42);
  }

  // Every command, every argument field, every wrong value: an error naming it, on one
  // connection that stays usable.
  LineClient c(path, 10000);
  int checked = 0;
  for (const auto& [cmd, args] : command_args()) {
    std::vector<std::string> fields{"id"};
    for (const auto& [k, v] : args.items()) fields.push_back(k);
    for (const auto& field : fields) {
      for (const auto& value : wrong_values()) {
        const std::string line = request_text(cmd, args, field, value);
        INFO(line.substr(0, 200));
        REQUIRE(c.send_raw(line + "\n"));
        const json r = parse(c.read_line());
        REQUIRE(r.is_object());
        ++checked;
        const std::string code = error_code_of(r);
        const json parsed = json::parse(value, nullptr, false);
        if (field == "id") {
          // Any JSON value is a valid id, echoed; only what JSON cannot hold is refused.
          if (parsed.is_discarded() || value.size() > 100)
            CHECK(code == "bad_json");
          else
            CHECK(r.value("id", json()) == parsed);
          continue;
        }
        if (field == "refresh" && parsed.is_boolean()) continue;  // right type
        CHECK(r.value("ok", true) == false);
        CHECK((code == "bad_argument" || code == "bad_json" || code == "not_powerlink"));
        if (code == "bad_argument") CHECK_THAT(error_message_of(r), Catch::Contains(field));
      }
    }
  }
  CHECK(checked > 500);
  CHECK(c.request({{"cmd", "status"}}).value("ok", false));

  // Alive, and still cycling.
  REQUIRE(d.running());
  uint64_t seen = d.shm().wait_start();
  std::error_code ec;
  CHECK(d.shm().wait(seen, 1, ds1928_shm_now_ns() + 5'000'000'000, ec) == ShmWait::Published);
}

TEST_CASE("clients that never read their replies: back-pressure, then closed, RSS stays bounded",
          "[daemon][socket][hostile]") {
  // Stated bound: the daemon's peak RSS grows by less than
  //   clients × (reply_buffer_bytes + max_request_bytes + 64 KiB) + 8 MiB
  // i.e. per client the reply buffer, its largest reply and read buffer, and 8 MiB for the
  // allocator's arenas and everything else. Without the bound every unread status reply (about
  // 2 kB) stayed queued: 10^5 requests per client would be 200 MB per client.
  constexpr int kClients = 8;
  constexpr long kReplyBuffer = 262144;  // the default
  constexpr long kMaxRequest = 4096;     // the default
  constexpr int kRequests = 100000;
  constexpr long kBoundKb = (kClients * (kReplyBuffer + kMaxRequest + 65536) + 8 * 1048576) / 1024;

  DaemonProcess d("noread", "reply_stall_timeout_ms: 1500");
  REQUIRE(d.wait_ready());
  {  // the daemon's steady state: one status served
    LineClient warm(d.socket_path(), 10000);
    REQUIRE(warm.request({{"cmd", "status"}}).value("ok", false));
  }
  const long hwm_before = d.vm_kb("VmHWM");
  const long rss_before = d.vm_kb("VmRSS");
  REQUIRE(hwm_before > 0);

  struct Conn {
    int fd = -1;
    int sent = 0;
    bool closed_by_daemon = false;
  };
  std::vector<Conn> conns(kClients);
  for (auto& c : conns) {
    c.fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, d.socket_path().c_str(), sizeof(addr.sun_path) - 1);
    REQUIRE(connect(c.fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0);
  }
  // Write requests until each connection has sent 10^5 or is closed by the daemon; never read.
  const std::string request = "{\"cmd\":\"status\"}\n";
  bool progress = true;
  while (progress) {
    std::vector<pollfd> fds;
    for (auto& c : conns) {
      while (!c.closed_by_daemon && c.sent < kRequests) {
        const ssize_t n = ::send(c.fd, request.data(), request.size(), MSG_NOSIGNAL);
        if (n == static_cast<ssize_t>(request.size())) {
          ++c.sent;
          continue;
        }
        if (n < 0 && (errno == EAGAIN || errno == EINTR)) break;
        c.closed_by_daemon = true;  // EPIPE / ECONNRESET
      }
      if (!c.closed_by_daemon && c.sent < kRequests) fds.push_back({c.fd, POLLOUT, 0});
    }
    if (fds.empty()) break;
    // The daemon either reads again or closes the connection after its stall timeout (1.5 s);
    // 20 s without either is a failure.
    progress = ::poll(fds.data(), fds.size(), 20000) > 0;
  }
  CHECK(progress);
  // A connection that got all its requests out must still be closed by the daemon.
  for (auto& c : conns) {
    if (c.closed_by_daemon) continue;
    pollfd p{c.fd, POLLIN, 0};
    if (::poll(&p, 1, 20000) > 0 && (p.revents & (POLLHUP | POLLERR)) != 0)
      c.closed_by_daemon = true;
  }
  const long hwm_after = d.vm_kb("VmHWM");
  const long rss_after = d.vm_kb("VmRSS");
  long sent = 0;
  int closed = 0;
  for (auto& c : conns) {
    sent += c.sent;
    closed += c.closed_by_daemon;
    ::close(c.fd);
  }
  WARN("non-reading clients: " << kClients << " × up to " << kRequests << " status requests; "
                               << sent << " accepted by the socket before back-pressure; "
                               << "daemon VmHWM " << hwm_before << " → " << hwm_after
                               << " kB, VmRSS " << rss_before << " → " << rss_after
                               << " kB; bound +" << kBoundKb << " kB");
  CHECK(closed == kClients);
  CHECK(sent < static_cast<long>(kClients) * kRequests);  // the daemon stopped reading
  CHECK(hwm_after - hwm_before < test::memory_bound_kb(kBoundKb));
  REQUIRE(d.running());
  // Each closing is logged (by the asynchronous logger, so after the client saw it).
  const std::size_t logged = d.log_count("bytes of replies unread", kClients);
  INFO("daemon log:\n" << d.log());
  CHECK(logged == kClients);
  // The daemon still answers.
  LineClient after(d.socket_path(), 10000);
  CHECK(after.request({{"cmd", "status"}}).value("ok", false));
}

TEST_CASE("10^5 garbage requests and 500 connections at once: every one answered, cycle goes on",
          "[daemon][socket][hostile]") {
  // max_clients 100: of the 500 connections opened while the 4 garbage connections are open, 96
  // become sessions and 404 get a too_many_clients refusal.
  constexpr int kMaxClients = 100;
  constexpr int kGarbageConns = 4;
  constexpr int kGarbagePerConn = 25000;
  constexpr int kBatch = 250;
  constexpr int kStorm = 500;
  test::raise_fd_limit();
  DaemonProcess d("storm", "max_clients: " + std::to_string(kMaxClients));
  REQUIRE(d.wait_ready());
  CycleWatch watch(d.shm_name());
  REQUIRE(watch.opened());

  std::vector<std::unique_ptr<LineClient>> garbage_conns;
  for (int i = 0; i < kGarbageConns; ++i) {
    garbage_conns.push_back(std::make_unique<LineClient>(d.socket_path(), 20000));
    REQUIRE(garbage_conns.back()->request({{"cmd", "status"}}).value("ok", false));
  }
  std::latch storm_done(1);
  std::atomic<int> answered{0}, unexpected{0};
  std::vector<std::thread> senders;
  for (int i = 0; i < kGarbageConns; ++i) {
    senders.emplace_back([&, i] {
      std::mt19937_64 rng(1000 + i);
      LineClient& c = *garbage_conns[i];
      for (int b = 0; b < kGarbagePerConn / kBatch; ++b) {
        std::string batch;
        for (int k = 0; k < kBatch; ++k) batch += garbage(rng, b * kBatch + k) + "\n";
        if (!c.send_raw(batch)) break;
        for (int k = 0; k < kBatch; ++k) {
          const json r = parse(c.read_line());
          const std::string code = error_code_of(r);
          if (code == "bad_json" || code == "bad_argument" || code == "unknown_command")
            ++answered;
          else if (unexpected++ == 0)
            WARN("unexpected reply " << r.dump() << " to a garbage line");
          if (!r.is_object()) return;  // connection lost: the count shows it
        }
      }
      storm_done.wait();  // stay a session until the storm's sessions are counted
    });
  }

  std::vector<std::unique_ptr<LineClient>> storm;
  for (int i = 0; i < kStorm; ++i) {
    storm.push_back(std::make_unique<LineClient>(d.socket_path(), 20000));
    REQUIRE(storm.back()->connected());
    (void)storm.back()->send_raw("{\"cmd\":\"status\"}\n");
  }
  int ok = 0, refused = 0, other = 0;
  for (auto& c : storm) {
    const json r = c->reply();
    if (r.is_object() && r.value("ok", false))
      ++ok;
    else if (error_code_of(r) == "too_many_clients")
      ++refused;
    else
      ++other;
  }
  storm.clear();
  storm_done.count_down();
  for (auto& t : senders) t.join();
  garbage_conns.clear();
  watch.stop();

  WARN("garbage: " << answered.load() << " error replies to " << kGarbageConns * kGarbagePerConn
                   << " requests; storm: " << ok << " sessions, " << refused
                   << " refused (max_clients " << kMaxClients << "); cycles advanced "
                   << watch.advanced() << ", largest gap between publications seen "
                   << watch.max_gap_ns() / 1000 << " µs, waits over 2 s: " << watch.stalls());
  CHECK(answered.load() == kGarbageConns * kGarbagePerConn);
  CHECK(unexpected.load() == 0);
  CHECK(ok == kMaxClients - kGarbageConns);
  CHECK(refused == kStorm - ok);
  CHECK(other == 0);
  CHECK(watch.stalls() == 0);
  CHECK(watch.advanced() > 0);
  REQUIRE(d.running());
  LineClient after(d.socket_path(), 10000);
  CHECK(after.request({{"cmd", "status"}}).value("ok", false));
}
