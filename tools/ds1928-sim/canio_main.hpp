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
  // Strict CANopen node (docs/canio.md): boots pre-operational; these loosen or fault it.
  bool self_start = false;       // operational right after the boot-up (no NMT Start needed)
  uint32_t heartbeat_ms = 0;     // heartbeat producer time at power-up (0x1017)
  bool config_readable = false;  // configuration registers answer reads (FM254: write-only)
  double reset_after_s = 0.0;    // reset by itself (brown-out: settings lost) after S seconds
  double stall_after_s = 0.0;    // acquisition stalls after S seconds ...
  uint32_t stall_for_ms = 0;     // ... for this long (0: for good)
  double emcy_after_s = 0.0;     // send one EMCY after S seconds
  uint32_t emcy_code = 0x7300;   // its error code (CiA 301: 0x73xx sensor)
  // The bus controller's identity (0x1000, 0x1018/1..4); -1: the config's canio.nodes[] entry,
  // else the simulator's placeholder (docs/canio.md §Node identity).
  int64_t device_type = -1, vendor_id = -1, product_code = -1, revision_no = -1, serial_no = -1;
  bool no_identity = false;  // 0x1000 / 0x1018 do not exist (abort 0x06020000)
  uint64_t seed = 1;
  double duration_s = 0.0;
};

// `reset`: set (SIGUSR1) to make the node reset by itself; taken back to false here.
int run_canio(const CanioOptions& options, const std::atomic<bool>& stop, std::atomic<bool>& reset);
