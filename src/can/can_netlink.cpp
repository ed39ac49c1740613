#include "can/can_netlink.hpp"

#include <linux/can/netlink.h>
#include <linux/if_link.h>
#include <linux/netlink.h>
#include <linux/rtnetlink.h>
#include <net/if.h>
#include <sys/socket.h>

#include <cerrno>
#include <cstring>
#include <vector>

#include "core/unique_fd.hpp"

namespace ds1928::canio {
namespace {

// Walks the rtattr list in [data, data + len), calling f(type, payload) for each well-formed
// attribute. False when an attribute runs past the end.
template <class F>
bool for_each_attr(const uint8_t* data, std::size_t len, F&& f) {
  while (len >= sizeof(rtattr)) {
    rtattr a;
    std::memcpy(&a, data, sizeof a);
    if (a.rta_len < sizeof(rtattr) || a.rta_len > len) return false;
    f(static_cast<uint16_t>(a.rta_type & NLA_TYPE_MASK),
      std::span<const uint8_t>(data + RTA_LENGTH(0), a.rta_len - RTA_LENGTH(0)));
    const std::size_t step = RTA_ALIGN(a.rta_len);
    if (step >= len) return true;
    data += step;
    len -= step;
  }
  return true;
}

template <class T>
bool read_as(std::span<const uint8_t> p, T& out) {
  if (p.size() < sizeof(T)) return false;
  std::memcpy(&out, p.data(), sizeof(T));
  return true;
}

std::string bring_up_command(std::string_view ifname, uint32_t bitrate) {
  const std::string n(ifname);
  const std::string rate = bitrate != 0 ? std::to_string(bitrate) : "<bit rate>";
  return "ip link set " + n + " down && ip link set " + n + " type can bitrate " + rate +
         " restart-ms 100 && ip link set " + n + " up";
}

}  // namespace

Result<CanLinkInfo> parse_link_message(std::span<const uint8_t> msg) noexcept {
  nlmsghdr h;
  if (msg.size() < sizeof h) return CanError::kNetlink;
  std::memcpy(&h, msg.data(), sizeof h);
  if (h.nlmsg_len > msg.size() || h.nlmsg_len < NLMSG_LENGTH(sizeof(ifinfomsg)))
    return CanError::kNetlink;
  if (h.nlmsg_type != RTM_NEWLINK) return CanError::kNetlink;
  ifinfomsg ifi;
  std::memcpy(&ifi, msg.data() + NLMSG_LENGTH(0), sizeof ifi);
  CanLinkInfo link;
  link.info.ifindex = ifi.ifi_index;
  link.info.up = (ifi.ifi_flags & IFF_UP) != 0;
  link.info.running = (ifi.ifi_flags & IFF_RUNNING) != 0;
  const std::size_t attrs_at = NLMSG_LENGTH(NLMSG_ALIGN(sizeof(ifinfomsg)));
  if (attrs_at > h.nlmsg_len) return CanError::kNetlink;
  bool ok = true;
  bool have_state = false;
  uint32_t state = 0;
  const bool walked = for_each_attr(
      msg.data() + attrs_at, h.nlmsg_len - attrs_at, [&](uint16_t type, auto payload) {
        if (type == IFLA_TXQLEN) {
          ok &= read_as(payload, link.info.txqueuelen);
          return;
        }
        if (type != IFLA_LINKINFO) return;
        ok &= for_each_attr(payload.data(), payload.size(), [&](uint16_t t, auto p) {
          if (t == IFLA_INFO_KIND) {
            std::size_t n = 0;
            while (n < p.size() && p[n] != 0) ++n;
            link.kind_name.assign(reinterpret_cast<const char*>(p.data()), n);
          } else if (t == IFLA_INFO_DATA) {
            ok &= for_each_attr(p.data(), p.size(), [&](uint16_t c, auto d) {
              switch (c) {
                case IFLA_CAN_STATE:
                  have_state = read_as(d, state);
                  ok &= have_state;
                  break;
                case IFLA_CAN_BITTIMING: {
                  can_bittiming bt{};
                  ok &= read_as(d, bt);
                  link.info.bitrate = bt.bitrate;
                  link.info.sample_point = bt.sample_point;
                  break;
                }
                case IFLA_CAN_RESTART_MS:
                  ok &= read_as(d, link.info.restart_ms);
                  break;
                case IFLA_CAN_CTRLMODE: {
                  can_ctrlmode cm{};
                  ok &= read_as(d, cm);
                  link.info.one_shot = (cm.flags & CAN_CTRLMODE_ONE_SHOT) != 0;
                  break;
                }
                case IFLA_CAN_BERR_COUNTER: {
                  can_berr_counter bc{};
                  link.info.error_counters_valid = read_as(d, bc);
                  ok &= link.info.error_counters_valid;
                  link.info.tx_error_count = bc.txerr;
                  link.info.rx_error_count = bc.rxerr;
                  break;
                }
                default:
                  break;
              }
            });
          }
        });
      });
  if (!walked || !ok) return CanError::kNetlink;
  link.kind = link.kind_name == "can"    ? LinkKind::Can
              : link.kind_name == "vcan" ? LinkKind::VirtualCan
                                         : LinkKind::Other;
  if (!link.info.up) {
    link.info.state = CanState::Down;
  } else if (link.kind == LinkKind::VirtualCan) {
    link.info.state = CanState::ErrorActive;  // a vcan has no controller
  } else if (have_state && state < CAN_STATE_MAX) {
    link.info.state = static_cast<CanState>(state);  // same order as enum can_state
  } else {
    link.info.state = CanState::Unknown;
  }
  return link;
}

Result<CanLinkInfo> query_can_link(std::string_view interface) noexcept {
  if (interface.empty() || interface.size() >= IFNAMSIZ) return CanError::kInterfaceNameInvalid;
  char name[IFNAMSIZ] = {};
  std::memcpy(name, interface.data(), interface.size());
  const unsigned index = if_nametoindex(name);
  if (index == 0) {
    if (errno == ENODEV || errno == ENXIO) return CanError::kNoSuchInterface;
    return std::error_code(errno, std::system_category());
  }
  UniqueFd fd(socket(AF_NETLINK, SOCK_RAW | SOCK_CLOEXEC, NETLINK_ROUTE));
  if (!fd.valid()) return std::error_code(errno, std::system_category());
  struct {
    nlmsghdr h;
    ifinfomsg ifi;
  } req{};
  req.h.nlmsg_len = NLMSG_LENGTH(sizeof(ifinfomsg));
  req.h.nlmsg_type = RTM_GETLINK;
  req.h.nlmsg_flags = NLM_F_REQUEST;
  req.h.nlmsg_seq = 1;
  req.ifi.ifi_family = AF_UNSPEC;
  req.ifi.ifi_index = static_cast<int>(index);
  sockaddr_nl kernel{};
  kernel.nl_family = AF_NETLINK;
  if (sendto(fd.get(), &req, req.h.nlmsg_len, 0, reinterpret_cast<sockaddr*>(&kernel),
             sizeof kernel) < 0)
    return std::error_code(errno, std::system_category());
  // One link's message with its statistics is a few KiB; 32 KiB leaves room for VF lists.
  std::vector<uint8_t> buf;
  try {
    buf.resize(32768);
  } catch (...) {
    return std::make_error_code(std::errc::not_enough_memory);
  }
  for (;;) {
    const ssize_t n = recv(fd.get(), buf.data(), buf.size(), 0);
    if (n < 0) {
      if (errno == EINTR) continue;
      return std::error_code(errno, std::system_category());
    }
    std::size_t off = 0;
    while (off + sizeof(nlmsghdr) <= static_cast<std::size_t>(n)) {
      nlmsghdr h;
      std::memcpy(&h, buf.data() + off, sizeof h);
      if (h.nlmsg_len < sizeof h || off + h.nlmsg_len > static_cast<std::size_t>(n))
        return CanError::kNetlink;
      if (h.nlmsg_seq == 1) {
        if (h.nlmsg_type == NLMSG_ERROR) {
          nlmsgerr e{};
          if (h.nlmsg_len >= NLMSG_LENGTH(sizeof e))
            std::memcpy(&e, buf.data() + off + NLMSG_LENGTH(0), sizeof e);
          if (e.error == -ENODEV) return CanError::kNoSuchInterface;
          return std::error_code(e.error != 0 ? -e.error : EPROTO, std::system_category());
        }
        if (h.nlmsg_type == RTM_NEWLINK)
          return parse_link_message(std::span<const uint8_t>(buf.data() + off, h.nlmsg_len));
      }
      off += NLMSG_ALIGN(h.nlmsg_len);
    }
  }
}

LinkVerdict check_can_link(std::string_view interface, const CanLinkInfo& link,
                           uint32_t expected_bitrate, bool require_up) {
  const std::string n(interface);
  if (link.kind == LinkKind::Other) {
    return {make_error_code(CanError::kNotCanInterface),
            "'" + n + "' is not a CAN interface (link kind '" +
                (link.kind_name.empty() ? std::string("none") : link.kind_name) +
                "'; ip -details link show " + n + ")"};
  }
  if (link.kind == LinkKind::Can && expected_bitrate != 0 && link.info.bitrate != 0 &&
      link.info.bitrate != expected_bitrate) {
    return {make_error_code(CanError::kBitrateMismatch),
            "CAN interface '" + n + "' runs at " + std::to_string(link.info.bitrate) +
                " bit/s, the configuration says " + std::to_string(expected_bitrate) + ": " +
                bring_up_command(interface, expected_bitrate)};
  }
  if (link.kind == LinkKind::Can && link.info.bitrate == 0) {
    return {make_error_code(CanError::kBitrateMismatch),
            "CAN interface '" + n +
                "' has no bit rate set: " + bring_up_command(interface, expected_bitrate)};
  }
  if (require_up && !link.info.up) {
    return {make_error_code(CanError::kInterfaceDown),
            "CAN interface '" + n + "' is down: " +
                (link.kind == LinkKind::Can ? bring_up_command(interface, expected_bitrate)
                                            : "ip link set " + n + " up")};
  }
  return {};
}

std::string describe_link_error(std::string_view interface, std::error_code error) {
  const std::string n(interface);
  if (error == CanError::kNoSuchInterface)
    return "no CAN interface '" + n + "' (ip link show " + n + ")";
  if (error == CanError::kInterfaceNameInvalid)
    return "CAN interface name '" + n + "' is empty or longer than " +
           std::to_string(IFNAMSIZ - 1) + " characters";
  return "CAN interface '" + n + "': " + error.message();
}

}  // namespace ds1928::canio
