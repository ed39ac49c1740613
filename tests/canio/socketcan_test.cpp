// SocketCanPort on a real kernel CAN stack. Runs where AF_CAN exists (the QEMU guest of the
// real-kernel test, or any Linux host with CAN); elsewhere it exits 77 (ctest: skipped) saying
// why.
//
// Interfaces: DS1928_CAN_IFACES="can0 can1" names two CAN controllers on one bus (default: can0
// and can1 when both exist); a CAN interface that is down is configured (500 kbit/s,
// restart-ms 100) and brought up, as root. A vcan named after the pid is created for the
// single-interface tests and removed at exit. Needs root for ip link.
#define CATCH_CONFIG_RUNNER
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "can/can_netlink.hpp"
#include "can/socketcan_port.hpp"
#include "support/alloc_counter.hpp"

using namespace ds1928::canio;

namespace {

struct Env {
  std::string vcan;          // created by this test ("" when vcan is unavailable)
  std::string can_a, can_b;  // two controllers on one bus ("" when absent)
  uint32_t can_bitrate = 0;  // as configured on can_a
  std::string single;        // the interface single-interface tests use
};
Env g_env;

const char* ip_command() {
  for (const char* p : {"/usr/sbin/ip", "/sbin/ip", "/usr/bin/ip", "/bin/ip"})
    if (access(p, X_OK) == 0) return p;
  return "ip";
}

bool ip(const std::string& args) {
  const std::string cmd = std::string(ip_command()) + " " + args + " 2>/dev/null";
  return std::system(cmd.c_str()) == 0;
}

int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Generous: the guest is a TCG-emulated CPU on a busy host.
constexpr int64_t kWait = 10'000'000'000;

bool usable_can(const std::string& name) {
  auto link = query_can_link(name);
  if (!link || link->kind != LinkKind::Can) return false;
  if (!link->info.up) {
    // Configure as docs/canio.md says (two commands: options after "type can" are CAN options).
    if (!ip("link set " + name + " type can bitrate 500000 restart-ms 100") ||
        !ip("link set " + name + " up"))
      return false;
  }
  // Right after "up" a link may still report no carrier: wait, bounded.
  for (int i = 0; i < 200; ++i) {
    auto l = query_can_link(name);
    if (l && l->info.up && l->info.running) return true;
    timespec pause{0, 10'000'000};
    nanosleep(&pause, nullptr);
  }
  return false;
}

std::unique_ptr<SocketCanPort> open_port(const std::string& name, uint32_t bitrate = 0) {
  SocketCanOptions o;
  o.interface = name;
  o.expected_bitrate = bitrate;
  auto r = SocketCanPort::open(o);
  INFO(r.message);
  REQUIRE(r.port);
  return std::move(r.port);
}

CanFrame frame(uint32_t id, uint8_t tag) {
  const uint8_t b[8] = {tag, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77};
  return make_standard_frame(id, b);
}

}  // namespace

TEST_CASE("bind, exact filters and error-frame subscription read back from the kernel",
          "[socketcan]") {
  auto port = open_port(g_env.single);
  auto s = port->read_settings();
  REQUIRE(s);
  CHECK(s->error_mask == kDefaultErrorMask);
  CHECK(s->timestamping);
  CHECK(s->rxq_overflow);
  const CanIdFilter ids[] = {{0x181, false}, {0x281, false}, {0x10000181, true}};
  REQUIRE_FALSE(port->set_filters(ids));
  s = port->read_settings();
  REQUIRE(s);
  CHECK(s->filter_count == 3);
  REQUIRE_FALSE(port->set_error_mask(err_class::kBusOff));
  CHECK(port->read_settings()->error_mask == err_class::kBusOff);
}

TEST_CASE("a frame with an unfiltered identifier is not received", "[socketcan]") {
  auto tx = open_port(g_env.single), rx = open_port(g_env.single);
  const CanIdFilter ids[] = {{0x181, false}};
  REQUIRE_FALSE(rx->set_filters(ids));
  REQUIRE(tx->send(frame(0x182, 1)).sent());
  REQUIRE(tx->send(frame(0x181 | 0x400, 2)).sent());
  REQUIRE(tx->send(frame(0x181, 3)).sent());
  std::array<CanFrame, 8> buf;
  auto r = rx->receive(buf, now_ns() + kWait);
  REQUIRE_FALSE(r.error);
  REQUIRE(r.count >= 1);
  CHECK(buf[0].id == 0x181);  // the earlier, unfiltered frames never arrived
  CHECK(buf[0].data[0] == 3);
  CHECK(r.count == 1);
  CHECK(rx->receive(buf, 0).count == 0);
}

TEST_CASE("non-blocking send and receive between two sockets, with kernel RX stamps",
          "[socketcan]") {
  auto tx = open_port(g_env.single), rx = open_port(g_env.single);
  const CanIdFilter ids[] = {{0x301, false}};
  REQUIRE_FALSE(rx->set_filters(ids));
  std::array<CanFrame, 8> buf;
  // Nothing there: a past deadline returns at once.
  CHECK(rx->receive(buf, 0).count == 0);
  int64_t last = 0;
  for (uint8_t i = 0; i < 20; ++i) {
    const int64_t before = now_ns();
    REQUIRE(tx->send(frame(0x301, i)).sent());
    auto r = rx->receive(buf, now_ns() + kWait);
    const int64_t after = now_ns();
    REQUIRE(r.count == 1);
    CHECK(buf[0].data[0] == i);
    CHECK(buf[0].rx_clock == RxClock::KernelSoftware);
    // Moved to CLOCK_MONOTONIC: between the send and the return of receive.
    CHECK(buf[0].rx_time_ns >= before);
    CHECK(buf[0].rx_time_ns <= after);
    CHECK(buf[0].rx_time_ns >= last);
    last = buf[0].rx_time_ns;
  }
  CHECK(rx->counters().rx_frames == 20);
  CHECK(rx->counters().rx_unstamped == 0);
  CHECK(tx->counters().tx_frames == 20);
}

TEST_CASE("frames cross the bus from one controller to the other", "[socketcan][pair]") {
  if (g_env.can_a.empty()) {
    WARN("no pair of CAN controllers (DS1928_CAN_IFACES / can0 + can1): skipped");
    return;
  }
  auto a = open_port(g_env.can_a, g_env.can_bitrate), b = open_port(g_env.can_b);
  const CanIdFilter ids[] = {{0x185, false}};
  REQUIRE_FALSE(b->set_filters(ids));
  std::array<CanFrame, 8> buf;
  for (uint8_t i = 0; i < 10; ++i) {
    const int64_t before = now_ns();
    REQUIRE(a->send(frame(0x185, i)).sent());
    auto r = b->receive(buf, now_ns() + kWait);
    REQUIRE(r.count == 1);
    CHECK(same_content(buf[0], frame(0x185, i)));
    CHECK(buf[0].rx_clock == RxClock::KernelSoftware);
    CHECK(buf[0].rx_time_ns >= before);
  }
}

TEST_CASE("two processes exchange frames over the two controllers", "[socketcan][pair]") {
  if (g_env.can_a.empty()) {
    WARN("no pair of CAN controllers: skipped");
    return;
  }
  auto master = open_port(g_env.can_a, g_env.can_bitrate);
  const CanIdFilter answers[] = {{0x181, false}, {0x701, false}};
  REQUIRE_FALSE(master->set_filters(answers));
  const pid_t child = fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    // The node on the other controller: answers every SYNC (0x080) with 0x181, byte 0 + 1.
    SocketCanOptions o;
    o.interface = g_env.can_b;
    auto opened = SocketCanPort::open(o);
    if (!opened.port) _exit(2);
    const CanIdFilter sync[] = {{0x080, false}};
    if (opened.port->set_filters(sync)) _exit(3);
    if (!opened.port->send(frame(0x701, 0)).sent()) _exit(4);  // ready
    std::array<CanFrame, 8> buf;
    for (int answered = 0; answered < 50;) {
      auto r = opened.port->receive(buf, now_ns() + kWait);
      if (r.error || r.count == 0) _exit(5);
      for (std::size_t i = 0; i < r.count; ++i, ++answered)
        if (!opened.port->send(frame(0x181, static_cast<uint8_t>(buf[i].data[0] + 1))).sent())
          _exit(6);
    }
    _exit(0);
  }
  std::array<CanFrame, 8> buf;
  auto ready = master->receive(buf, now_ns() + kWait);
  REQUIRE(ready.count == 1);
  CHECK(buf[0].id == 0x701);
  int answered = 0;
  for (int i = 0; i < 50; ++i) {
    REQUIRE(master->send(frame(0x080, static_cast<uint8_t>(i))).sent());
    auto r = master->receive(buf, now_ns() + kWait);
    REQUIRE(r.count == 1);
    answered += buf[0].id == 0x181 && buf[0].data[0] == static_cast<uint8_t>(i + 1);
  }
  CHECK(answered == 50);
  int status = 0;
  REQUIRE(waitpid(child, &status, 0) == child);
  CHECK(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 0);
}

TEST_CASE("interface state, bit rate and restart-ms from netlink, mismatch is refused",
          "[socketcan][pair]") {
  if (g_env.can_a.empty()) {
    WARN("no CAN controller: only the vcan is checked");
    auto port = open_port(g_env.single);
    auto info = port->query_interface();
    REQUIRE(info);
    CHECK(info->up);
    CHECK(info->state == CanState::ErrorActive);
    return;
  }
  auto port = open_port(g_env.can_a, g_env.can_bitrate);
  auto info = port->query_interface();
  REQUIRE(info);
  CHECK(info->up);
  CHECK(info->bitrate == g_env.can_bitrate);
  CHECK(info->state == CanState::ErrorActive);
  CHECK(port->state() == CanState::ErrorActive);
  auto link = query_can_link(g_env.can_a);
  REQUIRE(link);
  CHECK(link->kind == LinkKind::Can);

  SocketCanOptions o;
  o.interface = g_env.can_a;
  o.expected_bitrate = g_env.can_bitrate == 500'000 ? 250'000 : 500'000;
  auto wrong = SocketCanPort::open(o);
  CHECK_FALSE(wrong.port);
  CHECK(wrong.error == CanError::kBitrateMismatch);
  CHECK(wrong.message.find(std::to_string(g_env.can_bitrate) + " bit/s") != std::string::npos);
  CHECK(wrong.message.find("bitrate " + std::to_string(o.expected_bitrate)) != std::string::npos);
}

TEST_CASE("a full TX queue is reported and counted, never waited for", "[socketcan][pair]") {
  if (g_env.can_a.empty()) {
    WARN("no CAN controller (a vcan never fills its queue): skipped");
    return;
  }
  auto a = open_port(g_env.can_a, g_env.can_bitrate);
  uint64_t full = 0, sent = 0;
  for (int i = 0; i < 2000; ++i) {
    const auto r = a->send(frame(0x186, static_cast<uint8_t>(i)));
    REQUIRE((r.status == SendStatus::Sent || r.status == SendStatus::QueueFull));
    if (r.status == SendStatus::QueueFull) {
      CHECK((r.error_number == ENOBUFS || r.error_number == EAGAIN));
      ++full;
    } else {
      ++sent;
    }
  }
  CHECK(a->counters().tx_queue_full == full);
  CHECK(a->counters().tx_frames == sent);
  WARN("burst of 2000: " << sent << " sent, " << full << " refused with a full queue");
}

TEST_CASE("an interface that goes down: receive and send say so, open refuses it",
          "[socketcan][down]") {
  if (g_env.vcan.empty()) {
    WARN("no vcan of this test's own to take down: skipped");
    return;
  }
  auto port = open_port(g_env.vcan);
  REQUIRE(ip("link set " + g_env.vcan + " down"));
  std::array<CanFrame, 4> buf;
  auto r = port->receive(buf, now_ns() + kWait);
  CHECK(r.error == CanError::kInterfaceDown);
  CHECK(port->state() == CanState::Down);
  CHECK(port->send(frame(0x181, 1)).status == SendStatus::InterfaceDown);
  SocketCanOptions o;
  o.interface = g_env.vcan;
  auto refused = SocketCanPort::open(o);
  CHECK(refused.error == CanError::kInterfaceDown);
  CHECK(refused.message ==
        "CAN interface '" + g_env.vcan + "' is down: ip link set " + g_env.vcan + " up");
  REQUIRE(ip("link set " + g_env.vcan + " up"));
  CHECK(port->send(frame(0x181, 2)).sent());
}

TEST_CASE("missing and non-CAN interfaces are named", "[socketcan]") {
  SocketCanOptions o;
  o.interface = "nocan" + std::to_string(getpid() % 100000);
  auto missing = SocketCanPort::open(o);
  CHECK(missing.error == CanError::kNoSuchInterface);
  CHECK(missing.message ==
        "no CAN interface '" + o.interface + "' (ip link show " + o.interface + ")");
  o.interface = "lo";
  CHECK(SocketCanPort::open(o).error == CanError::kNotCanInterface);
}

TEST_CASE("send and receive on a kernel socket allocate nothing", "[socketcan][alloc]") {
  auto tx = open_port(g_env.single), rx = open_port(g_env.single);
  const CanIdFilter ids[] = {{0x381, false}};
  REQUIRE_FALSE(rx->set_filters(ids));
  std::array<CanFrame, 8> buf;
  std::size_t got = 0;
  ds1928::test::HeapCounts counts;
  {
    ds1928::test::ScopedCounting counting;
    for (int i = 0; i < 200; ++i) {
      (void)tx->send(frame(0x381, static_cast<uint8_t>(i)));
      got += rx->receive(buf, now_ns() + kWait).count;
    }
    counts = counting.stop();
  }
  CHECK(got == 200);
  CHECK(counts.allocations() == 0);
  CHECK(counts.mutex_locks == 0);
}

int main(int argc, char** argv) {
  if (auto e = probe_af_can()) {
    std::printf(
        "SKIP canio_socketcan_test: this kernel has no AF_CAN (socket(AF_CAN): %s). "
        "It runs inside the QEMU guest of the real-kernel test (docs/canio.md).\n",
        e.message().c_str());
    return 77;
  }
  std::vector<std::string> names;
  if (const char* env = std::getenv("DS1928_CAN_IFACES")) {
    std::istringstream in(env);
    for (std::string n; in >> n;) names.push_back(n);
  } else {
    names = {"can0", "can1"};
  }
  if (names.size() >= 2 && usable_can(names[0]) && usable_can(names[1])) {
    g_env.can_a = names[0];
    g_env.can_b = names[1];
    g_env.can_bitrate = query_can_link(names[0])->info.bitrate;
  }
  const std::string vcan = "vcant" + std::to_string(getpid() % 100000);
  if (geteuid() == 0 && ip("link add dev " + vcan + " type vcan") && ip("link set " + vcan + " up"))
    g_env.vcan = vcan;
  g_env.single = !g_env.vcan.empty() ? g_env.vcan : g_env.can_a;
  if (g_env.single.empty()) {
    std::printf(
        "SKIP canio_socketcan_test: AF_CAN exists but there is no usable CAN interface "
        "(no can0/can1, and no vcan: needs root and the vcan module).\n");
    return 77;
  }
  std::printf("canio_socketcan_test: single-interface tests on %s; controller pair: %s\n",
              g_env.single.c_str(),
              g_env.can_a.empty() ? "none" : (g_env.can_a + " + " + g_env.can_b).c_str());
  const int rc = Catch::Session().run(argc, argv);
  if (!g_env.vcan.empty()) (void)ip("link del dev " + g_env.vcan);
  return rc;
}
