// Where and with which permissions the shared memory is created (docs/configuration.md `shm:`).
#pragma once

#include <cstdint>
#include <string>

namespace ds1928 {

struct ShmConfig {
  std::string name = "/ds1928d";  // POSIX shm object name (/dev/shm/ds1928d)
  uint32_t mode = 0640;           // owner rw, group read-only
  std::string group;              // optional group owner
};

}  // namespace ds1928
