// A minimal in-memory Controlled Node for the MN tests: NMT states, IdentResponse,
// StatusResponse, PRes with a process image, an SDO server on a plain object map, and faults.
#pragma once

#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <vector>

#include "powerlink/link.hpp"
#include "powerlink/process_image.hpp"
#include "powerlink/sdo.hpp"

namespace ds1928::powerlink::test {

class TestCn : public SdoObjectAccess {
 public:
  TestCn(uint8_t node, NodeImageLayout layout);

  // A frame the MN sent; answers go to `out`.
  void on_frame(std::span<const uint8_t> frame, std::deque<std::vector<uint8_t>>& out);
  void power_cycle();

  uint32_t read_object(uint16_t index, uint8_t sub, std::span<uint8_t> out,
                       std::size_t& size) noexcept override;
  uint32_t write_object(uint16_t index, uint8_t sub,
                        std::span<const uint8_t> data) noexcept override;

  uint8_t node;
  MacAddress mac;
  NodeImageLayout layout;
  NmtState state = NmtState::kNotActive;
  std::map<std::pair<uint16_t, uint8_t>, std::vector<uint8_t>> objects;
  ModuleInputs inputs;         // what every module reports
  ModuleOutputs last_outputs;  // module 0's outputs from the last PReq
  bool last_preq_ready = false;
  std::vector<uint8_t> last_preq_payload;  // whole payload of the last PReq to this CN
  std::vector<uint8_t> pres_extra;         // raw PRes bytes after the modules' bytes
  uint64_t last_relative_time_us = 0;
  // Faults.
  bool drop_pres = false;
  bool pres_not_ready = false;            // PRes with RD = 0 also in OPERATIONAL
  std::optional<uint16_t> poll_out_size;  // PollOutSize reported instead of the layout's
  bool ignore_status_requests = false;
  bool ignore_sdo = false;     // SDO frames go unanswered (a transfer stays open until its timeout)
  int fake_request_count = 0;  // RS reported in the PRes although nothing is queued
  bool hold_pres = false;      // answer, but into held_pres (a late PRes)
  std::deque<std::vector<uint8_t>> held_pres;  // the test delivers these when it wants
  int pres_size_delta = 0;
  std::vector<ErrorEntry> status_errors;
  // An NMTRequest to send when invited (RS/PR = 7 announced in the PRes until then).
  std::optional<NmtRequest> nmt_request;
  int nmt_request_invites = 0;
  uint32_t vendor_id = 0x1A;
  uint32_t product_code = 0x1928;
  uint32_t device_type = 0;
  uint32_t serial_no = 0;
  // Exception signalling: EN in PRes and StatusResponse; the EA/ER the MN last sent.
  bool exception_new = false;
  bool last_preq_ea = false;
  int exception_resets = 0;  // StatusRequests with ER set
  // Error signalling handshake: EC follows the ER of the StatusRequest (set after power-up);
  // false = a CN that never answers EC=1.
  bool follow_er = true;
  bool exception_clear = true;
  bool last_er = false;
  std::vector<bool> er_seen;  // ER of every StatusRequest, in order
  // The next this many NMTResetConfiguration find the CN power-cycled meanwhile: it comes back
  // with no object written (nothing stored).
  int power_cycles_in_reset_configuration = 0;
  // Stays in PRE_OPERATIONAL_2 on NMTEnableReadyToOperate while set.
  bool hold_ready_to_operate = false;
  // Object writes: refused with this abort code (else communication objects 0x1000..0x1FFF and
  // the module objects are stored).
  std::map<std::pair<uint16_t, uint8_t>, uint32_t> write_aborts;
  std::vector<std::pair<uint16_t, uint8_t>> writes;  // in the order received
  // Seen.
  int nmt_commands = 0;
  std::vector<NmtCommandId> nmt_log;  // every NMT command to this CN, in order
  // State of the objects when the CN last passed RESET_CONFIGURATION (what it took).
  std::map<std::pair<uint16_t, uint8_t>, std::vector<uint8_t>> taken;
  int ident_requests = 0;
  int status_requests = 0;
  int reads = 0;  // SDO reads

 private:
  SdoServer server_;
  std::deque<std::vector<uint8_t>> sdo_out_;
};

// The wire: every frame the MN sends is given to the CNs at once; their answers are queued
// and received in order (deadlines are irrelevant in memory).
class MemoryLink : public Link {
 public:
  std::vector<TestCn*> cns;
  std::deque<std::vector<uint8_t>> rx;
  std::vector<std::vector<uint8_t>> sent_log;  // when logging
  bool log = false;
  bool up = true;
  std::function<void(std::span<const uint8_t>)>
      on_send;  // every frame the MN sent, after the CNs' answers were queued
  // receive() found nothing queued: the deadline a real link would have waited until.
  std::function<void(int64_t deadline_ns)> on_idle_wait;
  std::error_code send(std::span<const uint8_t> frame) noexcept override;
  Received receive(std::span<uint8_t> buffer, int64_t deadline_ns) noexcept override;
  bool link_up() const noexcept override { return up; }
  MacAddress mac() const noexcept override { return {0x02, 0, 0, 0, 0, 0xF0}; }
};

}  // namespace ds1928::powerlink::test
