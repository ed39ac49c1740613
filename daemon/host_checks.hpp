// The configuration against this host: what start would refuse and can be seen without
// privilege (interfaces, groups), for `ds1928d --check-config`. Start refuses the same things
// with the same words.
#pragma once

#include <string>
#include <vector>

#include "config/config.hpp"

namespace ds1928 {

// Each problem names its key and what is missing ("shm.group: no group 'ds1928' on this host
// ..."); empty: none.
[[nodiscard]] std::vector<std::string> host_problems(const DaemonConfig& config);

// What only a start on the running system can check, for this bus kind (one line).
[[nodiscard]] std::string checks_left_to_start(const DaemonConfig& config);

// "no group 'NAME' on this host (...)" when the group does not exist; empty when it does.
[[nodiscard]] std::string group_missing(const std::string& name);

}  // namespace ds1928
