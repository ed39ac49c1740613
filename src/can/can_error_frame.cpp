#include "can/can_error_frame.hpp"

#include <cstdio>

namespace ds1928::canio {

std::optional<CanState> CanErrorEvent::state_change() const noexcept {
  if (bus_off) return CanState::BusOff;
  if (restarted) return CanState::ErrorActive;
  if (controller) {
    if (controller_status & (err_ctrl::kRxPassive | err_ctrl::kTxPassive))
      return CanState::ErrorPassive;
    if (controller_status & (err_ctrl::kRxWarning | err_ctrl::kTxWarning))
      return CanState::ErrorWarning;
    if (controller_status & err_ctrl::kActive) return CanState::ErrorActive;
  }
  return std::nullopt;
}

Result<CanErrorEvent> decode_error_frame(const CanFrame& frame) noexcept {
  if (!frame.error) return CanError::kNotAnErrorFrame;
  if (frame.dlc != 8) return CanError::kErrorFrameLength;
  if ((frame.id & ~err_class::kAll) != 0) return CanError::kUnknownErrorClass;
  CanErrorEvent e;
  const uint32_t c = frame.id;
  const auto& d = frame.data;
  e.classes = c;
  e.tx_timeout = (c & err_class::kTxTimeout) != 0;
  e.lost_arbitration = (c & err_class::kLostArbitration) != 0;
  if (e.lost_arbitration) e.arbitration_bit = d[0];
  e.controller = (c & err_class::kController) != 0;
  if (e.controller) e.controller_status = d[1];
  e.protocol = (c & err_class::kProtocol) != 0;
  if (e.protocol) {
    e.protocol_type = d[2];
    e.protocol_location = d[3];
  }
  e.transceiver = (c & err_class::kTransceiver) != 0;
  if (e.transceiver) e.transceiver_status = d[4];
  e.no_ack = (c & err_class::kNoAck) != 0;
  e.bus_off = (c & err_class::kBusOff) != 0;
  e.bus_error = (c & err_class::kBusError) != 0;
  e.restarted = (c & err_class::kRestarted) != 0;
  e.controller_specific = d[5];
  e.counters_flagged = (c & err_class::kCounters) != 0;
  e.tx_error_count = d[6];
  e.rx_error_count = d[7];
  return e;
}

CanFrame encode_error_frame(const CanErrorEvent& e) noexcept {
  CanFrame f;
  f.error = true;
  f.dlc = 8;
  uint32_t c = 0;
  if (e.tx_timeout) c |= err_class::kTxTimeout;
  if (e.lost_arbitration) {
    c |= err_class::kLostArbitration;
    f.data[0] = e.arbitration_bit;
  }
  if (e.controller) {
    c |= err_class::kController;
    f.data[1] = e.controller_status;
  }
  if (e.protocol) {
    c |= err_class::kProtocol;
    f.data[2] = e.protocol_type;
    f.data[3] = e.protocol_location;
  }
  if (e.transceiver) {
    c |= err_class::kTransceiver;
    f.data[4] = e.transceiver_status;
  }
  if (e.no_ack) c |= err_class::kNoAck;
  if (e.bus_off) c |= err_class::kBusOff;
  if (e.bus_error) c |= err_class::kBusError;
  if (e.restarted) c |= err_class::kRestarted;
  if (e.counters_flagged) c |= err_class::kCounters;
  f.data[5] = e.controller_specific;
  f.data[6] = e.tx_error_count;
  f.data[7] = e.rx_error_count;
  f.id = c;
  return f;
}

namespace {

struct Writer {
  char* out;
  std::size_t size;
  std::size_t len = 0;
  void put(const char* s) noexcept {
    while (*s != '\0') {
      if (len + 1 < size) out[len] = *s;
      ++len;
      ++s;
    }
    if (size != 0) out[len < size ? len : size - 1] = '\0';
  }
  void sep() noexcept {
    if (len != 0) put("; ");
  }
};

const char* location_text(uint8_t loc) noexcept {
  switch (loc) {
    case 0x03:
      return "start of frame";
    case 0x02:
      return "identifier bits 28-21";
    case 0x06:
      return "identifier bits 20-18";
    case 0x04:
      return "substitute RTR";
    case 0x05:
      return "identifier extension";
    case 0x07:
      return "identifier bits 17-13";
    case 0x0F:
      return "identifier bits 12-5";
    case 0x0E:
      return "identifier bits 4-0";
    case 0x0C:
      return "RTR";
    case 0x0D:
      return "reserved bit 1";
    case 0x09:
      return "reserved bit 0";
    case 0x0B:
      return "data length code";
    case 0x0A:
      return "data section";
    case 0x08:
      return "CRC sequence";
    case 0x18:
      return "CRC delimiter";
    case 0x19:
      return "ACK slot";
    case 0x1B:
      return "ACK delimiter";
    case 0x1A:
      return "end of frame";
    case 0x12:
      return "intermission";
    default:
      return "unspecified location";
  }
}

}  // namespace

std::size_t describe(const CanErrorEvent& e, char* out, std::size_t size) noexcept {
  Writer w{out, size};
  if (size != 0) out[0] = '\0';
  if (e.bus_off) w.put("bus-off");
  if (e.restarted) {
    w.sep();
    w.put("controller restarted");
  }
  if (e.tx_timeout) {
    w.sep();
    w.put("TX timeout");
  }
  if (e.no_ack) {
    w.sep();
    w.put("no ACK on transmission");
  }
  if (e.lost_arbitration) {
    w.sep();
    w.put("lost arbitration");
  }
  if (e.controller) {
    w.sep();
    w.put("controller:");
    static constexpr struct {
      uint8_t bit;
      const char* text;
    } kCtrl[] = {{err_ctrl::kRxOverflow, " rx-overflow"}, {err_ctrl::kTxOverflow, " tx-overflow"},
                 {err_ctrl::kRxWarning, " rx-warning"},   {err_ctrl::kTxWarning, " tx-warning"},
                 {err_ctrl::kRxPassive, " rx-passive"},   {err_ctrl::kTxPassive, " tx-passive"},
                 {err_ctrl::kActive, " error-active"}};
    if (e.controller_status == 0) w.put(" unspecified");
    for (const auto& c : kCtrl)
      if (e.controller_status & c.bit) w.put(c.text);
  }
  if (e.protocol) {
    w.sep();
    w.put("protocol:");
    static constexpr struct {
      uint8_t bit;
      const char* text;
    } kProt[] = {{err_prot::kBit, " bit"},
                 {err_prot::kForm, " form"},
                 {err_prot::kStuff, " stuff"},
                 {err_prot::kBit0, " dominant-bit"},
                 {err_prot::kBit1, " recessive-bit"},
                 {err_prot::kOverload, " overload"},
                 {err_prot::kActive, " active-error"}};
    if ((e.protocol_type & 0x7F) == 0) w.put(" unspecified");
    for (const auto& p : kProt)
      if (e.protocol_type & p.bit) w.put(p.text);
    w.put(" error at ");
    w.put(location_text(e.protocol_location));
    if (e.protocol_type & err_prot::kTx) w.put(" (tx)");
  }
  if (e.transceiver) {
    w.sep();
    w.put("transceiver problem");
  }
  if (e.bus_error) {
    w.sep();
    w.put("bus error");
  }
  if (e.counters_flagged) {
    char buf[48];
    std::snprintf(buf, sizeof buf, "TEC %u REC %u", e.tx_error_count, e.rx_error_count);
    w.sep();
    w.put(buf);
  }
  if (w.len == 0) w.put("error frame without class");
  return w.len < size ? w.len : (size == 0 ? 0 : size - 1);
}

}  // namespace ds1928::canio
