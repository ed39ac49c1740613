#include "host_checks.hpp"

#include <grp.h>

#include <vector>

#include "powerlink/interface_check.hpp"

namespace ds1928 {

std::string group_missing(const std::string& name) {
  group grp{};
  group* found = nullptr;
  std::vector<char> buffer(16384);
  if (getgrnam_r(name.c_str(), &grp, buffer.data(), buffer.size(), &found) == 0 && found) return {};
  return "no group '" + name +
         "' on this host (the package creates it with systemd-sysusers; by hand: groupadd " + name +
         ")";
}

std::vector<std::string> host_problems(const DaemonConfig& c) {
  std::vector<std::string> problems;
  if (c.bus == BusKind::Powerlink && !c.powerlink.interface.empty()) {
    if (std::string m = powerlink::interface_missing(c.powerlink.interface); !m.empty()) {
      problems.push_back("powerlink.interface: " + m);
    } else if (std::string s = powerlink::shared_interface_reason(c.powerlink.interface);
               !s.empty() && !c.powerlink.allow_shared_interface) {
      problems.push_back("powerlink.interface: '" + c.powerlink.interface +
                         "' looks like a port of an IP network, not a POWERLINK segment: " + s +
                         " (start refuses it unless powerlink.allow_shared_interface: true)");
    }
  }
  if (c.bus == BusKind::Canio && c.canio.virtual_bus.empty())
    if (std::string m = powerlink::interface_missing(c.canio.interface); !m.empty())
      problems.push_back("canio.interface: " + m);
  if (!c.shm.group.empty())
    if (std::string m = group_missing(c.shm.group); !m.empty())
      problems.push_back("shm.group: " + m);
  if (!c.socket.group.empty())
    if (std::string m = group_missing(c.socket.group); !m.empty())
      problems.push_back("socket.group: " + m);
  return problems;
}

std::string checks_left_to_start(const DaemonConfig& c) {
  std::string bus;
  switch (c.bus) {
    case BusKind::Powerlink:
      bus = "the raw socket (root or CAP_NET_RAW), the link's carrier, the CNs' answers, ";
      break;
    case BusKind::Canio:
      bus = c.canio.virtual_bus.empty()
                ? "the CAN interface's state and bit rate, the nodes' answers, "
                : "the virtual bus, the nodes' answers, ";
      break;
    case BusKind::Simulated:
      break;
  }
  return "left to the start (they need the running system): " + bus +
         "real-time scheduling and memory locking, the shared memory name and the control "
         "socket's directory";
}

}  // namespace ds1928
