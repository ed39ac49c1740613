// The client side of CANopen expedited SDO (CiA 301): one transfer at a time to one node, as a
// pure state machine in the style of powerlink::SdoClient. The request frame comes out of read()
// or write(), the server's frames go in through receive(), time through the `now_ns` arguments;
// the owner sends and receives on its own loop (the CAN-I/O driver: the cycle thread, between
// two response windows). Nothing here sleeps, blocks, allocates or reads a clock.
//
// Only expedited transfers exist: every X20DS1928 register is 1, 2 or 4 bytes, so there is no
// segmented transfer and no toggle bit; a server that starts one is answered with the error
// kSegmentedNotSupported (sdo_expedited.hpp).
#pragma once

#include <cstdint>
#include <optional>
#include <system_error>

#include "can/can_frame.hpp"
#include "can/errors.hpp"
#include "canio/sdo_expedited.hpp"

namespace ds1928::canio {

// How a transfer ended.
struct SdoOutcome {
  // Empty on success; an SdoFrameError (the answer does not fit the request, or another size
  // than expected: kSizeMismatch, with value/size as answered) or a CiA 301 abort
  // (sdo_abort_category). Empty with timed_out set when no answer came in time.
  std::error_code error;
  bool timed_out = false;
  uint32_t value = 0;  // reads: the value answered
  uint8_t size = 0;    // reads: the data bytes answered (0: no answer)
};

class ExpeditedSdoClient {
 public:
  // Every transfer waits this long for its answer.
  explicit ExpeditedSdoClient(int64_t timeout_ns) noexcept : timeout_ns_(timeout_ns) {}

  // Start a transfer; the frame to send (0x600 + node). The transfer is in flight from `now_ns`
  // until an answer or the timeout. Refused (error) while busy() or for an invalid node/size.
  // `expected_size` 0 accepts any size 1..4 for a read.
  [[nodiscard]] Result<CanFrame> read(uint8_t node, uint16_t index, uint8_t subindex,
                                      uint8_t expected_size, int64_t now_ns) noexcept;
  [[nodiscard]] Result<CanFrame> write(uint8_t node, uint16_t index, uint8_t subindex, uint8_t size,
                                       uint32_t value, int64_t now_ns) noexcept;

  // A frame from the SDO port. The outcome when it is the server's answer (0x580 + node of the
  // transfer in flight); frames of other nodes, error and remote frames are not its business.
  [[nodiscard]] std::optional<SdoOutcome> receive(const CanFrame& frame) noexcept;
  // The outcome (timed_out) when the answer is overdue at `now_ns`.
  [[nodiscard]] std::optional<SdoOutcome> tick(int64_t now_ns) noexcept;
  // Forget the transfer in flight (its request could not be sent); a late answer is then no
  // transfer's.
  void cancel() noexcept { busy_ = false; }

  [[nodiscard]] bool busy() const noexcept { return busy_; }
  [[nodiscard]] uint8_t node() const noexcept { return node_; }
  [[nodiscard]] int64_t deadline_ns() const noexcept { return deadline_ns_; }

 private:
  [[nodiscard]] Result<CanFrame> start(uint8_t node, const SdoMessage& request,
                                       uint8_t expected_size, int64_t now_ns) noexcept;

  int64_t timeout_ns_;
  bool busy_ = false;
  uint8_t node_ = 0;
  uint8_t expected_size_ = 0;
  SdoMessage request_{};
  int64_t deadline_ns_ = 0;
};

}  // namespace ds1928::canio
