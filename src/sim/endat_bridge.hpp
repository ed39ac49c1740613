// The EnDat part of the simulated X20DS1928's firmware: takes one complete Flatstream message
// (a command of X20DS1928.md §7), runs it as EnDat wire transactions against the encoder with
// CRC checks and retries, and yields the reply message once the simulated processing time has
// passed. It also reads the identification registers at power-up and on rescan, keeps
// EnDatError/EnDatWarning, serves EnDatAck, and reads positions with position frames.
//
// Time-driven, single-threaded, no clocks: every call carries the caller's now (ns). A command's
// wire transactions run at once in simulated time (the channel then stays busy until the reply is
// due), so a message can never interleave with another job's memory-area selection. What the
// module answers when a transaction fails is this project's decision: docs/endat.md.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <system_error>

#include "endat/command.hpp"
#include "endat/ident.hpp"
#include "sim/endat_encoder.hpp"

namespace ds1928::sim {

struct BridgeConfig {
  unsigned max_retries = 2;                 // per wire transaction, after the first attempt
  int64_t no_response_timeout_ns = 50'000;  // the master's wait for a start bit
  int64_t frame_interval_ns = 200'000;      // EnDat cycle: spacing of frames fetching AI words
  int64_t status_refresh_ns =
      500'000'000;               // re-read status words 0/1 when idle; 0 = only on events
  unsigned max_info_frames = 8;  // frames to wait for valid additional information
};

struct BridgeReply {
  endat::ReplyMessage message;
  int64_t ready_ns = 0;  // when the module had it ready
  [[nodiscard]] std::span<const uint8_t> bytes() const noexcept { return message.span(); }
};

struct PositionReading {
  uint64_t steps = 0;          // last CRC-checked position (kept when this frame failed)
  bool fresh = false;          // this call delivered a CRC-checked position
  bool encoder_error = false;  // F1 set: the encoder flags its position as invalid
  std::error_code error;       // why not fresh: no_response, crc_mismatch, f2_not_inverted, ...
};

// The module's identification registers (X20DS1928.md §6), exactly the encoder's words.
struct IdentRegisters {
  std::array<uint16_t, 16> operating_param{};       // OperatingParam_00..15 ← MRS 0xA7
  std::array<uint16_t, 4> operating_status{};       // OperatingStatus_00..03 ← MRS 0xB9
  endat::ManufacturerWords manufacturer{};          // ParamManuf_04..47 ← MRS 0xA1/A3/A5
  std::array<uint16_t, 64> manufacturer_endat22{};  // ParamManufEnDat22_01..63 ← MRS 0xBD
  bool valid = false;
};

struct BridgeStats {
  uint64_t transactions = 0;
  uint64_t retries = 0;
  uint64_t crc_errors = 0;  // frames whose CRC (or F1/F2 check) failed
  uint64_t no_responses = 0;
  uint64_t messages = 0;
  uint64_t failed_messages = 0;
};

class EnDatBridge {
 public:
  explicit EnDatBridge(EnDatEncoder encoder, BridgeConfig config = {});

  // Module power-up: reads the identification now; the channel stays busy as long as that takes.
  // Error: the first wire failure, or invalid_identification (EnDatParSetError is then set).
  std::error_code power_up(int64_t now_ns);
  // Module power-up with the EnDat interface disabled (function model 254's default): the
  // encoder is not read, the identification registers stay empty and no position can be read
  // until a Rescan (EnDatAck bit 1) reads them.
  void power_up_unread() noexcept;

  // One complete Flatstream message. False while another message is queued or its reply has
  // not been collected (one command at a time, as the module handles them).
  [[nodiscard]] bool submit(std::span<const uint8_t> message, int64_t now_ns);
  // The reply, once its processing time has passed; also runs due internal jobs.
  [[nodiscard]] std::optional<BridgeReply> poll(int64_t now_ns);
  // No message queued, in flight or waiting to be collected.
  [[nodiscard]] bool idle() const noexcept;
  // When the channel finishes its current job (for callers that want to sleep until then).
  [[nodiscard]] int64_t busy_until_ns() const noexcept { return channel_free_ns_; }

  // One position frame (the module's EnDat cycle).
  PositionReading read_position(int64_t now_ns);
  void set_position(uint64_t steps) noexcept { encoder_.set_position(steps); }
  // Clock pulses of the position value (from the identification; 0 before it was read).
  [[nodiscard]] unsigned position_bits() const noexcept { return position_bits_; }

  // EnDatAck register write: bit 0 acknowledge EnDat errors/warnings, bit 1 rescan.
  void endat_ack(uint8_t bits, int64_t now_ns);
  // EnDatAck as read back: a bit stays set until its algorithm has run on the wire (§11.6.2.3:
  // "the system resets the bit automatically and runs the algorithm"; the strict reading is that
  // the bit clears once the algorithm is done).
  [[nodiscard]] uint8_t endat_ack_pending(int64_t now_ns) const noexcept {
    return static_cast<uint8_t>(((pending_ack_ || now_ns < ack_done_ns_) ? 0x01 : 0) |
                                ((pending_rescan_ || now_ns < rescan_done_ns_) ? 0x02 : 0));
  }

  [[nodiscard]] uint16_t endat_error() const noexcept { return ident_.operating_status[0]; }
  [[nodiscard]] uint16_t endat_warning() const noexcept { return ident_.operating_status[1]; }
  // ErrorInfo bits the EnDat side owns: EnDatComError, EnDatPosError, EnDatParSetError.
  [[nodiscard]] uint8_t error_info() const noexcept { return latched_ | present_; }
  // AckErrorInfo: clears latched bits whose condition is gone.
  void acknowledge_error_info(uint8_t bits) noexcept;

  [[nodiscard]] const IdentRegisters& ident() const noexcept { return ident_; }
  [[nodiscard]] const std::optional<endat::Identification>& identification() const noexcept {
    return identification_;
  }
  // Identification registers and EnDatError/EnDatWarning by datasheet number; nullopt for
  // registers that are not the bridge's.
  [[nodiscard]] std::optional<uint16_t> read_register(uint16_t reg) const noexcept;

  [[nodiscard]] EnDatEncoder& encoder() noexcept { return encoder_; }
  [[nodiscard]] const BridgeStats& stats() const noexcept { return stats_; }

 private:
  struct Pending {
    endat::Message<16> bytes;
    bool too_long = false;
    int64_t submitted_ns = 0;
  };

  void service(int64_t now_ns);
  endat::ReplyMessage run_message(const Pending& p, int64_t& t);
  std::error_code run_rescan(int64_t& t);
  std::error_code run_acknowledge(int64_t& t);
  std::error_code run_status_refresh(int64_t& t);
  std::error_code run_info(const endat::Request& r, int64_t& t, std::array<uint16_t, 4>& words);

  template <class Decode, class Accept>
  std::error_code transact_retrying(int64_t& t, const endat::wire::BitFrame& frame, Decode decode,
                                    Accept accept);
  // One parameter-type transaction (select/read/write/reset) with echo check and retries.
  std::error_code param_tx(int64_t& t, endat::wire::Mode mode, uint8_t address, uint16_t parameter,
                           bool echo_value, uint16_t* value_out);
  // One position-type transaction (2.2 modes answered with a position frame) with retries.
  std::error_code position_tx(int64_t& t, endat::wire::Mode mode, uint8_t address,
                              uint16_t parameter, endat::wire::PositionReply* out);
  std::error_code read_area(int64_t& t, uint8_t mrs, unsigned first, std::span<uint16_t> out);
  [[nodiscard]] Result<endat::wire::PositionReply> decode_position(const endat::wire::BitFrame& f,
                                                                   endat::CommandSet set) const;
  [[nodiscard]] int64_t wire_ns(std::size_t bits) const noexcept;
  void note_failure(std::error_code ec) noexcept;
  void update_f1(bool f1, int64_t now_ns) noexcept;
  [[nodiscard]] endat::CommandSet command_set() const noexcept;

  EnDatEncoder encoder_;
  BridgeConfig config_;
  IdentRegisters ident_;
  std::optional<endat::Identification> identification_;
  unsigned position_bits_ = 0;

  std::optional<Pending> pending_;
  std::optional<BridgeReply> in_flight_;
  bool reset_in_flight_ = false;
  bool pending_ack_ = false;
  bool pending_rescan_ = false;
  bool status_due_ = false;
  int64_t status_due_ns_ = 0;
  int64_t ack_request_ns_ = 0;
  int64_t rescan_request_ns_ = 0;
  int64_t ack_done_ns_ = INT64_MIN;
  int64_t rescan_done_ns_ = INT64_MIN;
  int64_t channel_free_ns_ = INT64_MIN;
  int64_t last_status_ns_ = 0;

  uint8_t latched_ = 0;
  uint8_t present_ = 0;
  bool last_f1_ = false;
  uint64_t last_position_ = 0;
  BridgeStats stats_;
};

}  // namespace ds1928::sim
