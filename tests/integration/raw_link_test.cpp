// RawLink on a real veth pair. Each test case runs as its own process (ctest), moves itself into a
// fresh network namespace (unshare) and builds its veth pair there, so nothing leaks into the
// host's network. Needs root (CAP_SYS_ADMIN, CAP_NET_RAW); without it each case says so and
// passes vacuously — the namespace integration test has the same requirement and skips too.
#include "powerlink/raw_link.hpp"

#include <arpa/inet.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <sched.h>
#include <sys/socket.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdlib>
#include <cstring>
#include <string>

#include "core/clock.hpp"
#include "support/wait.hpp"

namespace pl = ds1928::powerlink;

namespace {

// Fresh namespace with veth pair rl_a <-> rl_b, both up. False (with a message) without privilege.
bool enter_test_namespace() {
  if (geteuid() != 0) {
    WARN("SKIPPED: RawLink tests need root (network namespace, raw sockets)");
    return false;
  }
  if (unshare(CLONE_NEWNET) != 0) {
    WARN("SKIPPED: unshare(CLONE_NEWNET) failed: " << std::strerror(errno));
    return false;
  }
  const int rc = std::system(
      "ip link add rl_a type veth peer name rl_b && ip link set rl_a up && ip link set rl_b up");
  REQUIRE(rc == 0);
  return true;
}

// Waits until the kernel reports carrier on both ends (link watch runs asynchronously).
void wait_link_up(const pl::RawLink& link) {
  REQUIRE(ds1928::test::wait_until([&] { return link.link_up(); }));
}

pl::RawLink open_link(const char* name, pl::RxMode mode) {
  pl::RawLink link;
  pl::RawLinkOptions o;
  o.interface = name;
  o.rx_mode = mode;
  o.carrier_check_interval_ns = 1'000'000;
  const std::error_code ec = link.open(o);
  INFO("open " << name << ": " << ec.message());
  REQUIRE_FALSE(ec);
  return link;
}

std::array<uint8_t, 20> short_powerlink_frame(const pl::MacAddress& src) {
  std::array<uint8_t, 20> f{};
  std::memcpy(f.data(), pl::kMacSoA.data(), 6);
  std::memcpy(f.data() + 6, src.data(), 6);
  f[12] = 0x88;
  f[13] = 0xAB;
  f[14] = 0x05;  // SoA
  f[15] = 0xFF;
  f[16] = 0xF0;
  for (std::size_t i = 17; i < f.size(); ++i) f[i] = static_cast<uint8_t>(0xA0 + i);
  return f;
}

}  // namespace

TEST_CASE("RawLink pads short frames to 60 bytes and time-stamps arrival, in every RX mode") {
  if (!enter_test_namespace()) return;
  for (const pl::RxMode mode : {pl::RxMode::Ring, pl::RxMode::BusyPoll, pl::RxMode::Blocking}) {
    INFO("rx mode " << pl::to_string(mode));
    pl::RawLink a = open_link("rl_a", mode);
    pl::RawLink b = open_link("rl_b", mode);
    wait_link_up(a);
    const auto frame = short_powerlink_frame(a.mac());
    const int64_t sent_at = ds1928::rt::now_ns();
    REQUIRE_FALSE(a.send(frame));
    std::array<uint8_t, 1514> rx{};
    const pl::Received r = b.receive(rx, ds1928::rt::now_ns() + 200'000'000);
    REQUIRE_FALSE(r.error);
    REQUIRE(r.length == 60);
    CHECK(std::memcmp(rx.data(), frame.data(), frame.size()) == 0);
    for (std::size_t i = frame.size(); i < 60; ++i) CHECK(rx[i] == 0);
    CHECK(r.rx_time_ns >= sent_at - 1'000'000);
    CHECK(r.rx_time_ns <= ds1928::rt::now_ns());
    // Nothing else pending: the receive times out at its deadline with length 0.
    const int64_t t0 = ds1928::rt::now_ns();
    const pl::Received none = b.receive(rx, t0 + 2'000'000);
    CHECK(none.length == 0);
    CHECK_FALSE(none.error);
    CHECK(ds1928::rt::now_ns() - t0 >= 2'000'000);
  }
}

TEST_CASE("RawLink receives only POWERLINK frames and refuses oversized ones") {
  if (!enter_test_namespace()) return;
  pl::RawLink a = open_link("rl_a", pl::RxMode::Ring);
  pl::RawLink b = open_link("rl_b", pl::RxMode::Ring);
  wait_link_up(a);
  // An IPv4-typed frame through a plain packet socket: b's link must not deliver it.
  const int raw = socket(AF_PACKET, SOCK_RAW, 0);
  REQUIRE(raw >= 0);
  sockaddr_ll addr{};
  addr.sll_family = AF_PACKET;
  addr.sll_ifindex = static_cast<int>(if_nametoindex("rl_a"));
  addr.sll_halen = 6;
  std::array<uint8_t, 60> ip{};
  std::memset(ip.data(), 0xFF, 6);
  ip[12] = 0x08;
  ip[13] = 0x00;
  REQUIRE(sendto(raw, ip.data(), ip.size(), 0, reinterpret_cast<sockaddr*>(&addr), sizeof addr) ==
          60);
  close(raw);
  std::array<uint8_t, 1514> rx{};
  CHECK(b.receive(rx, ds1928::rt::now_ns() + 20'000'000).length == 0);

  std::array<uint8_t, 1515> big{};
  CHECK(a.send(big) == pl::RawLinkErrc::kFrameTooLong);
  std::array<uint8_t, 10> tiny{};
  CHECK(a.send(tiny) == pl::RawLinkErrc::kFrameTooShort);
}

TEST_CASE("RawLink reports carrier loss and an interface that vanished") {
  if (!enter_test_namespace()) return;
  pl::RawLink a = open_link("rl_a", pl::RxMode::Ring);
  wait_link_up(a);
  const auto frame = short_powerlink_frame(a.mac());
  // Peer down: rl_a stays administratively up but loses its carrier.
  REQUIRE(std::system("ip link set rl_b down") == 0);
  CHECK(ds1928::test::wait_until([&] {
    (void)a.send(frame);  // the carrier check runs from send()
    return !a.link_up();
  }));
  CHECK(a.stats().link_losses == 1);
  REQUIRE(std::system("ip link set rl_b up") == 0);
  wait_link_up(a);  // link_up() itself notices the carrier coming back

  // The interface disappears: sends fail with an errno naming it, the link is down.
  REQUIRE(std::system("ip link del rl_a") == 0);
  std::error_code ec;
  (void)ds1928::test::wait_until([&] {
    ec = a.send(frame);
    return static_cast<bool>(ec);
  });
  INFO("send after delete: " << ec.message());
  CHECK((ec == std::errc::no_such_device_or_address || ec == std::errc::network_down ||
         ec == std::errc::no_such_device));
  CHECK_FALSE(a.link_up());
}
