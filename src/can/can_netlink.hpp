// Reads a CAN interface's state, bit timing and restart setting over rtnetlink (RTM_GETLINK →
// IFLA_LINKINFO → IFLA_INFO_KIND "can"/"vcan" and IFLA_INFO_DATA → IFLA_CAN_STATE,
// IFLA_CAN_BITTIMING, IFLA_CAN_RESTART_MS, IFLA_CAN_BERR_COUNTER).
//
// Written on plain netlink rather than libsocketcan: the port needs four attributes of one
// message, which is a short request/response parse, and it keeps the daemon free of a library
// whose other half (configuring the interface) the daemon must not do anyway — bit rate and
// restart-ms are the administrator's `ip link` settings, which the daemon only verifies.
// Normal thread only (one netlink socket per call, small stack buffers).
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <system_error>

#include "can/can_port.hpp"
#include "can/errors.hpp"

namespace ds1928::canio {

// Kind of link as IFLA_INFO_KIND names it.
enum class LinkKind : uint8_t { Can = 0, VirtualCan = 1, Other = 2 };

struct CanLinkInfo {
  CanInterfaceInfo info;
  LinkKind kind = LinkKind::Other;
  std::string kind_name;  // IFLA_INFO_KIND as reported ("can", "vcan", "veth", ... or "")
};

// kNoSuchInterface, kNotCanInterface (kind is neither can nor vcan), kNetlink (socket or parse
// failure: the error says which), or the info. A vcan has no bit timing: bitrate 0, state
// error-active while up.
[[nodiscard]] Result<CanLinkInfo> query_can_link(std::string_view interface) noexcept;

// The start-up verdict on an interface against the configured bit rate (0: not checked):
// no error when usable, else kInterfaceDown / kBitrateMismatch / kNotCanInterface and the message
// for the user naming the values and the `ip link` command that fixes it, e.g. "CAN interface
// 'can0' runs at 250000 bit/s, the configuration says 500000: ip link set can0 down && ip link
// set can0 type can bitrate 500000 restart-ms 100 && ip link set can0 up". A vcan has no bit
// rate and is accepted at any configured one.
struct LinkVerdict {
  std::error_code error;
  std::string message;
};
[[nodiscard]] LinkVerdict check_can_link(std::string_view interface, const CanLinkInfo& link,
                                         uint32_t expected_bitrate, bool require_up = true);

// Parses one RTM_NEWLINK message (nlmsghdr included) as the kernel answers RTM_GETLINK. Pure:
// tested with built messages. kNetlink names what was malformed in the returned error's
// message only as a code; attribute lengths are all checked.
[[nodiscard]] Result<CanLinkInfo> parse_link_message(std::span<const uint8_t> message) noexcept;

// The message for a query_can_link() failure, e.g. "no CAN interface 'can0' (ip link show can0)".
[[nodiscard]] std::string describe_link_error(std::string_view interface, std::error_code error);

}  // namespace ds1928::canio
