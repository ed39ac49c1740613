#include "powerlink/interface_check.hpp"

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <net/if.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <fstream>
#include <sstream>
#include <string_view>
#include <vector>

namespace ds1928::powerlink {
namespace {

[[nodiscard]] int prefix_length(const sockaddr* mask) {
  if (mask == nullptr) return -1;
  const auto* bytes =
      mask->sa_family == AF_INET
          ? reinterpret_cast<const uint8_t*>(&reinterpret_cast<const sockaddr_in*>(mask)->sin_addr)
          : reinterpret_cast<const uint8_t*>(
                &reinterpret_cast<const sockaddr_in6*>(mask)->sin6_addr);
  const int n = mask->sa_family == AF_INET ? 4 : 16;
  int bits = 0;
  for (int i = 0; i < n; ++i) bits += __builtin_popcount(bytes[i]);
  return bits;
}

// IPv6 link-local (fe80::/10) addresses are on every interface that is up, POWERLINK's too;
// only the others tell of an IPv6 network.
[[nodiscard]] bool global_ipv6(const in6_addr& a) {
  return !IN6_IS_ADDR_LINKLOCAL(&a) && !IN6_IS_ADDR_LOOPBACK(&a) && !IN6_IS_ADDR_UNSPECIFIED(&a);
}

[[nodiscard]] std::vector<std::string> addresses(const std::string& interface) {
  std::vector<std::string> found;
  ifaddrs* list = nullptr;
  if (getifaddrs(&list) != 0) return found;
  for (const ifaddrs* i = list; i != nullptr; i = i->ifa_next) {
    if (i->ifa_addr == nullptr || interface != i->ifa_name) continue;
    char text[INET6_ADDRSTRLEN] = {};
    if (i->ifa_addr->sa_family == AF_INET) {
      const auto* a = reinterpret_cast<const sockaddr_in*>(i->ifa_addr);
      inet_ntop(AF_INET, &a->sin_addr, text, sizeof text);
    } else if (i->ifa_addr->sa_family == AF_INET6) {
      const auto* a = reinterpret_cast<const sockaddr_in6*>(i->ifa_addr);
      if (!global_ipv6(a->sin6_addr)) continue;
      inet_ntop(AF_INET6, &a->sin6_addr, text, sizeof text);
    } else {
      continue;
    }
    const int prefix = prefix_length(i->ifa_netmask);
    found.push_back(prefix >= 0 ? std::string(text) + "/" + std::to_string(prefix) : text);
  }
  freeifaddrs(list);
  return found;
}

// /proc/self/net/route (not /proc/net: hidden under the unit's ProcSubset=pid): "Iface Destination
// Gateway Flags ..." with the destination in hex; /proc/self/net/ipv6_route: "dest dest_len src
// src_len next_hop metric refcnt use flags iface". Both describe the reader's network namespace.
[[nodiscard]] bool has_default_route(const std::string& interface) {
  {
    std::ifstream f("/proc/self/net/route");
    std::string line;
    std::getline(f, line);  // the header
    while (std::getline(f, line)) {
      std::istringstream in(line);
      std::string iface;
      std::string destination;
      std::string gateway;
      std::string flags;
      std::string refcnt;
      std::string use;
      std::string metric;
      std::string mask;
      if (in >> iface >> destination >> gateway >> flags >> refcnt >> use >> metric >> mask &&
          iface == interface && destination == "00000000" && mask == "00000000")
        return true;
    }
  }
  std::ifstream f("/proc/self/net/ipv6_route");
  std::string line;
  while (std::getline(f, line)) {
    std::istringstream in(line);
    std::vector<std::string> fields;
    for (std::string w; in >> w;) fields.push_back(w);
    if (fields.size() == 10 && fields[9] == interface && fields[1] == "00" &&
        fields[0] == std::string(32, '0'))
      return true;
  }
  return false;
}

}  // namespace

std::string interface_missing(const std::string& interface) {
  if (if_nametoindex(interface.c_str()) != 0) return {};
  return "no network interface '" + interface +
         "' on this host (`ip -br link` lists them; in a network namespace, check there)";
}

std::string shared_interface_reason(const std::string& interface) {
  std::string why;
  const std::vector<std::string> found = addresses(interface);
  for (std::size_t i = 0; i < found.size(); ++i)
    why += (i == 0 ? (found.size() == 1 ? "it has the address " : "it has the addresses ") : ", ") +
           found[i];
  if (has_default_route(interface))
    why += (why.empty() ? "it" : " and") + std::string(" carries the default route");
  return why;
}

}  // namespace ds1928::powerlink
