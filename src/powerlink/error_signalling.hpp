// POWERLINK error signalling (EPSG DS 301 §6.5, docs/powerlink.md §Error signalling), both
// roles, as pure state machines: flags in, flags and entries out; no I/O, no clock, no
// allocation (fixed storage), so the CN's and the MN's cycle paths can call them.
//
// The flags:
//   ER (SoA, MN → CN): exception reset. The MN starts the signalling with a CN by StatusRequests
//      carrying ER=1 until the CN's StatusResponse has EC=1, then ER=0 until EC=0.
//   EC (StatusResponse, CN → MN): exception clear. Set by the CN after its own reset (so the MN
//      sees the reboot and starts again) and while ER=1; cleared when ER goes back to 0.
//   EN (PRes / StatusResponse / IdentResponse, CN → MN): exception new. Toggled by the CN when
//      it queues an entry in its emergency queue and the previous toggle is acknowledged.
//   EA (PReq and SoA to the CN, MN → CN): exception acknowledge. The MN sets EA = EN once it has
//      fetched the CN's entries by a StatusRequest.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "powerlink/frames.hpp"

namespace ds1928::powerlink {

// Error entry type (u16) bits, EPSG DS 301 error entry layout.
namespace entry_type {
inline constexpr uint16_t kStatus = 0x8000;     // bit 15: status entry (a current error state)
inline constexpr uint16_t kEmergency = 0x4000;  // bit 14: queued for the MN (emergency queue)
inline constexpr uint16_t kModeMask = 0x3000;   // bits 13..12
inline constexpr uint16_t kModeActive = 0x1000;
inline constexpr uint16_t kModeCleared = 0x2000;
inline constexpr uint16_t kModeOccurred = 0x3000;
inline constexpr uint16_t kProfileMask = 0x0FFF;  // bits 11..0
inline constexpr uint16_t kProfileVendor = 0x0001;
inline constexpr uint16_t kProfilePowerlink = 0x0002;
}  // namespace entry_type

// Static error bit field byte 0 = ERR_ErrorRegister_U8 (0x1001); bit 0 = generic error.
inline constexpr uint8_t kErrorRegisterGeneric = 0x01;

// "0x8245 (POWERLINK, occurred, emergency) at 12.000345000 s, info 00 00 .." for status/log
// (normal thread; allocates).
[[nodiscard]] std::string describe(const ErrorEntry& e);

// ---- CN role ----------------------------------------------------------------------------------
class CnErrorSignalling {
 public:
  static constexpr std::size_t kQueueDepth = 8;  // emergency queue entries kept

  // After power-up and every NMT reset: EC=1 (the MN sees the reboot), EN=0, queue empty.
  void reset() noexcept;

  // A StatusRequest for this node: its SoA's ER and EA. An ER edge 0→1 sets EC and clears EN;
  // 1→0 clears EC and EN (the MN starts counting toggles afresh). Apply before answering: the
  // StatusResponse to this request already carries the new EC.
  void on_status_request(bool er, bool ea) noexcept;
  // A PReq for this node: its EA.
  void on_preq(bool ea) noexcept;

  // Queues an entry (the emergency bit is set); the oldest unsent entry is dropped when full.
  // Toggles EN unless a previous toggle still waits for its EA.
  void queue(ErrorEntry e) noexcept;

  [[nodiscard]] bool exception_new() const noexcept { return en_; }
  [[nodiscard]] bool exception_clear() const noexcept { return ec_; }
  [[nodiscard]] uint64_t static_error_bits() const noexcept;
  // The queue as it goes into the next StatusResponse. Call status_sent() once it went out: the
  // entries sent are dropped when the MN acknowledges the EN they were signalled with.
  [[nodiscard]] std::span<const ErrorEntry> entries() const noexcept {
    return {queue_.data(), count_};
  }
  void status_sent() noexcept;

  [[nodiscard]] uint32_t dropped() const noexcept { return dropped_; }  // queue overflows

 private:
  void acknowledge(bool ea) noexcept;

  bool ec_ = true;
  bool en_ = false;
  bool ea_ = false;       // last EA from the MN
  bool last_er_ = false;  // last ER from the MN (edges count)
  std::array<ErrorEntry, kQueueDepth> queue_{};
  std::size_t count_ = 0;
  std::size_t sent_ = 0;  // the first `sent_` entries went out in a StatusResponse
  uint32_t dropped_ = 0;
};

// ---- MN role ----------------------------------------------------------------------------------
enum class ErrSigState : uint8_t {
  kInitWaitEc1,  // StatusRequests with ER=1 until the StatusResponse has EC=1
  kInitWaitEc0,  // ER=0 until EC=0
  kReady,        // initialised: EN toggles are fetched and acknowledged
  kGaveUp,       // no handshake within the bound: the node runs without error signalling
};
[[nodiscard]] std::string_view to_string(ErrSigState s) noexcept;

class MnErrorSignalling {
 public:
  // StatusRequests of one handshake phase before the MN gives up on it (the node keeps working,
  // its EN toggles are still fetched).
  static constexpr uint32_t kMaxAttempts = 20;

  // The node was (re)identified: start the handshake again.
  void restart() noexcept;

  // Flags for a StatusRequest to this node (SoA) and for its PReq.
  [[nodiscard]] bool exception_reset() const noexcept {
    return state_ == ErrSigState::kInitWaitEc1;
  }
  [[nodiscard]] bool exception_acknowledge() const noexcept { return ea_; }
  // The MN wants a StatusRequest to this node soon: the handshake runs, or EN toggled.
  [[nodiscard]] bool status_request_due() const noexcept;

  // A StatusRequest to this node went out (counts toward the bound during the handshake).
  void on_status_request_sent() noexcept;
  // The node's EN in a PRes (or IdentResponse): a toggle against EA asks for its entries.
  void on_exception_new(bool en) noexcept;
  // A StatusResponse: advances the handshake; in kReady its entries are taken and EA = EN.
  // Returns true when the entries are new (to be recorded): in kReady with EN ≠ EA before.
  [[nodiscard]] bool on_status_response(bool en, bool ec) noexcept;

  [[nodiscard]] ErrSigState state() const noexcept { return state_; }
  [[nodiscard]] uint32_t attempts() const noexcept { return attempts_; }
  [[nodiscard]] bool fetch_pending() const noexcept { return fetch_; }
  [[nodiscard]] uint32_t handshakes() const noexcept { return handshakes_; }
  [[nodiscard]] uint32_t gave_up() const noexcept { return gave_up_; }

 private:
  ErrSigState state_ = ErrSigState::kInitWaitEc1;
  uint32_t attempts_ = 0;  // StatusRequests in the current phase
  bool ea_ = false;
  bool fetch_ = false;  // EN ≠ EA seen: fetch the entries
  uint32_t handshakes_ = 0;
  uint32_t gave_up_ = 0;
};

}  // namespace ds1928::powerlink
