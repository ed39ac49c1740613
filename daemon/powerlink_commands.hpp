// Socket commands for raw POWERLINK process data: pl-pres (last PRes payload of a CN) and
// pl-preq-set (bytes of a CN's PReq payload outside the X20DS1928 module regions).
#pragma once

#include <string>

#include "control/control_server.hpp"
#include "powerlink/powerlink_bus.hpp"

namespace ds1928 {

// `bus` outlives the server. pl-preq-set needs uid 0 or membership of `privileged_group` (as
// endat-write-param). On other buses the daemon answers not_powerlink (register_bus_commands).
void register_powerlink_commands(control::Server& server, powerlink::PowerlinkBus& bus,
                                 std::string privileged_group = {});

}  // namespace ds1928
