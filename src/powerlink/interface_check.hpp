// What the host says about the network interface POWERLINK is to own, read without privilege
// (start refuses the same things; `ds1928d --check-config` reports them before a start).
#pragma once

#include <string>

namespace ds1928::powerlink {

// Empty when the interface exists in this network namespace; else why not ("no network
// interface 'enp99s0' on this host (ip -br link lists them)").
[[nodiscard]] std::string interface_missing(const std::string& interface);

// Why the interface looks like a port of an IP network rather than a POWERLINK segment of its
// own: its IPv4 addresses, its global IPv6 addresses and whether it carries a default route,
// e.g. "it has the address 192.168.1.5/24 and carries the default route". Empty: none of them.
// POWERLINK's SoC and PReq go out every cycle: on a shared port they flood the IP network and its
// traffic delays the isochronous frames (a CN misses its PReq).
[[nodiscard]] std::string shared_interface_reason(const std::string& interface);

}  // namespace ds1928::powerlink
