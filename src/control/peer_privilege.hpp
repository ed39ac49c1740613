// Who may send the control socket's commands that change the encoder or the bus (write
// parameter / block, reset, raw PReq writes, captures): a Unix group lookup on the peer's
// SO_PEERCRED credentials.
#pragma once

#include <string>

#include "control/control_server.hpp"

namespace ds1928::control {

// Whether `peer` is uid 0, or a member of `group_name`: the peer's own gid, the user's primary
// group or one of its supplementary groups (getgrouplist). An empty or unknown group name, an
// unknown peer (uid -1) or a uid without a passwd entry is not privileged. Blocks on NSS
// (files, LDAP, ...): normal threads only.
[[nodiscard]] bool peer_is_privileged(const PeerCredentials& peer, const std::string& group_name);

}  // namespace ds1928::control
