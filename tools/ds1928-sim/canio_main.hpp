// ds1928-sim canio: options and entry point (canio_main.cpp).
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

struct CanioOptions {
  std::string iface;        // SocketCAN interface
  std::string virtual_bus;  // or: the cross-process virtual bus of this name
  int node = 1;
  int modules = 1;
  uint32_t bitrate = 0;  // checked against the interface (0: the config's, else unchecked)
  std::string byte_order = "little";
  bool no_sync = false;
  uint32_t sync_id = 0x080;
  std::string config_file;
  double drop = 0.0;
  uint32_t wrong_length_every = 0;
  uint32_t unexpected_id = 0;
  bool no_sdo = false;
  uint32_t sync_reaction_us = 50;  // ASSUMPTION: bus-controller reaction to SYNC
  double late_object2 = 0.0;
  uint32_t late_object2_us = 0;  // 0: one cycle (the config's period) or 2000
  std::string answer_log;        // file: "sync slot position pos_cycle" per answer
  double silent_after_s = 0.0;
  uint32_t silent_for_ms = 0;
  bool power_cycle_when_back = false;
  uint64_t seed = 1;
  double duration_s = 0.0;
};

int run_canio(const CanioOptions& options, const std::atomic<bool>& stop);
