// Errors of the EnDat layer: the Flatstream command codec, the EnDat wire frames, identification
// decoding and number parsing. One std::error_category ("endat"); related codes are grouped by
// std::error_condition so callers can ask "was it an echo mismatch?" without listing every field.
// Calls return a Result (core/result.hpp) holding one of these codes.
#pragma once

#include <system_error>
#include <type_traits>

#include "core/result.hpp"

namespace ds1928::endat {

enum class Errc : int {
  // Reply messages from the module (X20DS1928.md §7).
  truncated_reply = 1,      // fewer bytes than the command's reply has
  oversized_reply,          // more bytes than the command's reply has
  command_echo_mismatch,    // first reply byte is not the command byte
  mrs_echo_mismatch,        // echoed MRS code differs from the request's
  block_echo_mismatch,      // echoed block number differs
  parameter_echo_mismatch,  // echoed parameter number differs
  // Requests (encoding on the master, strict decoding on the module side).
  unknown_command,   // not one of 0x00, 0x01, 0x04..0x0B
  requires_endat22,  // command 0x06..0x0B sent to an EnDat 2.1 encoder
  invalid_mrs,       // MRS code outside the range the command accepts
  truncated_request,
  oversized_request,
  // Failure replies of the module (docs/endat.md, "Failure replies").
  module_crc_failure,         // EnDat CRC still wrong after the module's retries
  module_no_response,         // the encoder did not answer
  module_not_supported,       // the encoder does not support the command
  module_malformed_request,   // the module could not parse the request
  module_wire_echo_mismatch,  // the encoder's address echo on the wire was wrong
  module_unknown_failure,     // failure reply with a reason code this version does not know
  truncated_failure_reply,    // failure marker without its reason byte
  oversized_failure_reply,
  // Verification of a write by reading back.
  write_not_applied,
  // EnDat wire frames (simulated encoder and module firmware).
  no_response,      // no start bit: the encoder did not answer
  crc_mismatch,     // received CRC differs from the computed one
  frame_length,     // frame has the wrong number of bits
  invalid_mode,     // 6 mode bits are not a known mode command
  f2_not_inverted,  // EnDat 2.2 position frame with F2 == F1
  // Identification.
  invalid_identification,  // manufacturer words contradict themselves
  // Number parsing (command-line arguments).
  invalid_number,
  number_out_of_range,
};

// Groups of codes.
enum class Condition : int {
  echo_mismatch = 1,  // any *_echo_mismatch
  module_failure,     // any module_* failure reply
  malformed_reply,    // length or echo wrong: the bytes cannot be trusted
  bad_request,        // the request itself cannot be sent
};

[[nodiscard]] const std::error_category& error_category() noexcept;
[[nodiscard]] const std::error_category& condition_category() noexcept;

[[nodiscard]] inline std::error_code make_error_code(Errc e) noexcept {
  return {static_cast<int>(e), error_category()};
}
[[nodiscard]] inline std::error_condition make_error_condition(Condition c) noexcept {
  return {static_cast<int>(c), condition_category()};
}

}  // namespace ds1928::endat

template <>
struct std::is_error_code_enum<ds1928::endat::Errc> : std::true_type {};
template <>
struct std::is_error_condition_enum<ds1928::endat::Condition> : std::true_type {};
