// The rtnetlink side of the SocketCAN port, on any kernel: RTM_NEWLINK messages built here parse
// to the right state, bit rate and restart-ms; malformed ones are refused; the start-up verdicts
// name the values and the fix; real queries of a missing and a non-CAN interface; and what
// SocketCanPort::open says on a kernel without AF_CAN.
#include <linux/can/netlink.h>
#include <linux/if_link.h>
#include <linux/netlink.h>
#include <linux/rtnetlink.h>
#include <net/if.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstring>
#include <string>
#include <vector>

#include "can/can_netlink.hpp"
#include "can/socketcan_port.hpp"

using namespace ds1928::canio;

namespace {

// Builds netlink attributes the way the kernel lays them out (4-byte aligned, nested).
class MessageBuilder {
 public:
  MessageBuilder(unsigned flags, int ifindex) {
    buf_.resize(NLMSG_LENGTH(sizeof(ifinfomsg)));
    ifinfomsg ifi{};
    ifi.ifi_index = ifindex;
    ifi.ifi_flags = flags;
    std::memcpy(buf_.data() + NLMSG_LENGTH(0), &ifi, sizeof ifi);
  }
  std::size_t begin(uint16_t type) {
    const std::size_t at = buf_.size();
    attr(type, nullptr, 0);
    return at;
  }
  void end(std::size_t at) {
    const auto len = static_cast<uint16_t>(buf_.size() - at);
    std::memcpy(buf_.data() + at, &len, sizeof len);
  }
  void attr(uint16_t type, const void* data, std::size_t len) {
    rtattr a{};
    a.rta_len = static_cast<uint16_t>(RTA_LENGTH(len));
    a.rta_type = type;
    const std::size_t at = buf_.size();
    buf_.resize(at + RTA_ALIGN(a.rta_len));
    std::memcpy(buf_.data() + at, &a, sizeof a);
    if (len) std::memcpy(buf_.data() + at + RTA_LENGTH(0), data, len);
  }
  template <class T>
  void attr(uint16_t type, const T& v) {
    attr(type, &v, sizeof v);
  }
  std::vector<uint8_t> finish(uint16_t type = RTM_NEWLINK) {
    nlmsghdr h{};
    h.nlmsg_len = static_cast<uint32_t>(buf_.size());
    h.nlmsg_type = type;
    std::memcpy(buf_.data(), &h, sizeof h);
    return buf_;
  }

 private:
  std::vector<uint8_t> buf_;
};

std::vector<uint8_t> can_link(unsigned flags, const char* kind, uint32_t state, uint32_t bitrate,
                              uint32_t restart_ms) {
  MessageBuilder b(flags, 7);
  b.attr(IFLA_IFNAME, "can0", 5);
  b.attr(IFLA_TXQLEN, uint32_t{10});
  const auto li = b.begin(IFLA_LINKINFO);
  b.attr(IFLA_INFO_KIND, kind, std::strlen(kind) + 1);
  if (std::strcmp(kind, "can") == 0) {
    const auto data = b.begin(IFLA_INFO_DATA);
    can_bittiming bt{};
    bt.bitrate = bitrate;
    bt.sample_point = 875;
    b.attr(IFLA_CAN_BITTIMING, bt);
    b.attr(IFLA_CAN_STATE, state);
    b.attr(IFLA_CAN_RESTART_MS, restart_ms);
    can_ctrlmode cm{CAN_CTRLMODE_ONE_SHOT | CAN_CTRLMODE_BERR_REPORTING,
                    restart_ms == 0 ? 0u : unsigned{CAN_CTRLMODE_ONE_SHOT}};
    b.attr(IFLA_CAN_CTRLMODE, cm);
    can_berr_counter bc{12, 3};
    b.attr(IFLA_CAN_BERR_COUNTER, bc);
    b.end(data);
  }
  b.end(li);
  return b.finish();
}

}  // namespace

TEST_CASE("an RTM_NEWLINK of a CAN interface parses to state, bit rate, restart-ms",
          "[canio][netlink]") {
  auto msg = can_link(IFF_UP | IFF_RUNNING, "can", CAN_STATE_ERROR_PASSIVE, 500'000, 100);
  auto link = parse_link_message(msg);
  REQUIRE(link);
  CHECK(link->kind == LinkKind::Can);
  CHECK(link->kind_name == "can");
  CHECK(link->info.ifindex == 7);
  CHECK(link->info.up);
  CHECK(link->info.running);
  CHECK(link->info.state == CanState::ErrorPassive);
  CHECK(link->info.bitrate == 500'000);
  CHECK(link->info.sample_point == 875);
  CHECK(link->info.restart_ms == 100);
  CHECK(link->info.error_counters_valid);
  CHECK(link->info.tx_error_count == 12);
  CHECK(link->info.rx_error_count == 3);
  CHECK(link->info.txqueuelen == 10);  // what a stale replay after a silence is bounded by
  CHECK(link->info.one_shot);
  CHECK_FALSE(parse_link_message(can_link(IFF_UP, "can", 0, 500'000, 0))->info.one_shot);
  CHECK(parse_link_message(can_link(IFF_UP, "can", CAN_STATE_BUS_OFF, 1'000'000, 0))->info.state ==
        CanState::BusOff);
  CHECK(parse_link_message(can_link(0, "can", CAN_STATE_STOPPED, 500'000, 0))->info.state ==
        CanState::Down);
  auto vcan = parse_link_message(can_link(IFF_UP, "vcan", 0, 0, 0));
  REQUIRE(vcan);
  CHECK(vcan->kind == LinkKind::VirtualCan);
  CHECK(vcan->info.state == CanState::ErrorActive);
  CHECK(parse_link_message(can_link(IFF_UP, "veth", 0, 0, 0))->kind == LinkKind::Other);
}

TEST_CASE("malformed netlink answers are refused, never read past their end", "[canio][netlink]") {
  auto good = can_link(IFF_UP, "can", 0, 500'000, 100);
  for (std::size_t cut = 0; cut < good.size(); ++cut) {
    std::vector<uint8_t> m(good.begin(), good.begin() + cut);
    if (m.size() >= sizeof(nlmsghdr)) {
      // The header still claims the full length: must be refused.
      auto r = parse_link_message(m);
      CHECK_FALSE(r);
    }
  }
  CHECK(parse_link_message(good).has_value());
  CHECK(parse_link_message(MessageBuilder(IFF_UP, 1).finish(RTM_DELLINK)).error() ==
        CanError::kNetlink);
  // An attribute whose length runs past the message.
  auto bad = good;
  const std::size_t first_attr = NLMSG_LENGTH(NLMSG_ALIGN(sizeof(ifinfomsg)));
  const uint16_t huge = 0x7FFF;
  std::memcpy(bad.data() + first_attr, &huge, sizeof huge);
  CHECK(parse_link_message(bad).error() == CanError::kNetlink);
  // A CAN state attribute too short to hold its u32.
  MessageBuilder b(IFF_UP, 3);
  const auto li = b.begin(IFLA_LINKINFO);
  b.attr(IFLA_INFO_KIND, "can", 4);
  const auto data = b.begin(IFLA_INFO_DATA);
  const uint16_t short_state = 0;
  b.attr(IFLA_CAN_STATE, short_state);
  b.end(data);
  b.end(li);
  CHECK(parse_link_message(b.finish()).error() == CanError::kNetlink);
}

TEST_CASE("start-up verdicts name the values and the ip link command", "[canio][netlink]") {
  auto can = parse_link_message(can_link(IFF_UP | IFF_RUNNING, "can", 0, 250'000, 100)).value();
  CHECK_FALSE(check_can_link("can0", can, 250'000).error);
  CHECK_FALSE(check_can_link("can0", can, 0).error);  // not checked
  auto mismatch = check_can_link("can0", can, 500'000);
  CHECK(mismatch.error == CanError::kBitrateMismatch);
  CHECK(mismatch.message ==
        "CAN interface 'can0' runs at 250000 bit/s, the configuration says 500000: ip link set "
        "can0 down && ip link set can0 type can bitrate 500000 restart-ms 100 && ip link set can0 "
        "up");
  auto down = parse_link_message(can_link(0, "can", CAN_STATE_STOPPED, 500'000, 100)).value();
  auto verdict = check_can_link("can1", down, 500'000);
  CHECK(verdict.error == CanError::kInterfaceDown);
  CHECK(verdict.message.rfind("CAN interface 'can1' is down: ip link set can1 down && ", 0) == 0);
  CHECK_FALSE(check_can_link("can1", down, 500'000, false).error);
  auto unset = parse_link_message(can_link(0, "can", CAN_STATE_STOPPED, 0, 0)).value();
  CHECK(check_can_link("can0", unset, 500'000)
            .message.rfind("CAN interface 'can0' has no bit rate set", 0) == 0);
  auto vcan = parse_link_message(can_link(IFF_UP, "vcan", 0, 0, 0)).value();
  CHECK_FALSE(check_can_link("vcan0", vcan, 500'000).error);  // a vcan has no bit rate
  auto veth = parse_link_message(can_link(IFF_UP, "veth", 0, 0, 0)).value();
  auto not_can = check_can_link("eth0", veth, 500'000);
  CHECK(not_can.error == CanError::kNotCanInterface);
  CHECK(not_can.message ==
        "'eth0' is not a CAN interface (link kind 'veth'; ip -details link show eth0)");
  CHECK(describe_link_error("can0", make_error_code(CanError::kNoSuchInterface)) ==
        "no CAN interface 'can0' (ip link show can0)");
}

TEST_CASE("real rtnetlink queries: a missing interface and one that is not CAN",
          "[canio][netlink]") {
  const std::string missing = "nocan" + std::to_string(getpid() % 100000);
  CHECK(query_can_link(missing).error() == CanError::kNoSuchInterface);
  CHECK(query_can_link("").error() == CanError::kInterfaceNameInvalid);
  CHECK(query_can_link("a-name-far-too-long-for-linux").error() == CanError::kInterfaceNameInvalid);
  auto lo = query_can_link("lo");
  REQUIRE(lo);
  CHECK(lo->kind == LinkKind::Other);
  CHECK(lo->info.up);
  CHECK(lo->info.ifindex == static_cast<int>(if_nametoindex("lo")));
  CHECK(check_can_link("lo", *lo, 500'000).error == CanError::kNotCanInterface);
}

TEST_CASE("SocketCanPort::open names what is missing", "[canio][netlink]") {
  SocketCanOptions o;
  o.interface = "nocan" + std::to_string(getpid() % 100000);
  auto open = SocketCanPort::open(o);
  REQUIRE_FALSE(open.port);
  if (probe_af_can()) {
    // This kernel has no CAN at all: said so, not "no interface".
    CHECK(probe_af_can() == std::errc::address_family_not_supported);
    CHECK(open.error == CanError::kNoCanSupport);
    CHECK(open.message.find("this kernel has no AF_CAN") == 0);
    CHECK(open.message.find("modprobe can-raw") != std::string::npos);
  } else {
    CHECK(open.error == CanError::kNoSuchInterface);
    CHECK(open.message ==
          "no CAN interface '" + o.interface + "' (ip link show " + o.interface + ")");
    o.interface = "lo";
    auto lo = SocketCanPort::open(o);
    CHECK(lo.error == CanError::kNotCanInterface);
  }
}
