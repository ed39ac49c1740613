// The ten EnDat commands of the X20DS1928 in Flatstream mode (X20DS1928.md §7): request bytes
// the master sends as one Flatstream message and the reply message the module returns.
// Pure codec, usable on both sides: the daemon encodes requests and decodes replies strictly;
// the simulated module decodes requests strictly and encodes replies.
//
// Failure replies: the datasheet does not say what the module answers when the EnDat
// transaction fails. This project's module side answers with two bytes, 0x80 | command and a
// FailureReason (docs/endat.md); decode_reply() turns them into the matching module_* error.
// No valid reply begins with 0x80 | command, so the marker cannot be mistaken for data.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <system_error>

#include "endat/error.hpp"

namespace ds1928::endat {

enum class Command : uint8_t {
  Reset = 0x00,
  AcknowledgeErrors = 0x01,
  ReadParameter = 0x04,
  WriteParameter = 0x05,
  ReadBlockParameter = 0x06,   // EnDat 2.2 only
  WriteBlockParameter = 0x07,  // EnDat 2.2 only
  ReadInfoWord1 = 0x08,        // EnDat 2.2 only
  ReadInfoWord2 = 0x09,        // EnDat 2.2 only
  ReadInfoWord3 = 0x0A,        // EnDat 2.2 only
  ReadInfoWord4 = 0x0B,        // EnDat 2.2 only
};

inline constexpr std::array<Command, 10> kAllCommands{
    Command::Reset,          Command::AcknowledgeErrors,  Command::ReadParameter,
    Command::WriteParameter, Command::ReadBlockParameter, Command::WriteBlockParameter,
    Command::ReadInfoWord1,  Command::ReadInfoWord2,      Command::ReadInfoWord3,
    Command::ReadInfoWord4};

// Which EnDat command set the encoder speaks (manufacturer word 37, endat.md §4).
enum class CommandSet : uint8_t { EnDat21 = 1, EnDat22 = 2 };

inline constexpr std::size_t kMaxRequestBytes = 6;
inline constexpr std::size_t kMaxReplyBytes = 10;
inline constexpr uint8_t kFailureMarker = 0x80;

[[nodiscard]] std::optional<Command> command_from_byte(uint8_t byte) noexcept;
[[nodiscard]] std::string_view command_name(Command c) noexcept;
[[nodiscard]] bool requires_endat22(Command c) noexcept;
[[nodiscard]] bool has_mrs(Command c) noexcept;
[[nodiscard]] bool has_block(Command c) noexcept;
[[nodiscard]] bool has_parameter(Command c) noexcept;
[[nodiscard]] bool is_write(Command c) noexcept;
[[nodiscard]] bool is_info_read(Command c) noexcept;
// 1..4 for ReadInfoWord1..4, 0 otherwise.
[[nodiscard]] unsigned info_word_count(Command c) noexcept;
[[nodiscard]] std::size_t request_size(Command c) noexcept;
[[nodiscard]] std::size_t reply_size(Command c) noexcept;

// MRS ranges the commands accept: memory areas 0xA0..0xBF for parameter access, additional
// information selections 0x40..0x5F for the info-word reads.
[[nodiscard]] bool is_memory_area_mrs(uint8_t mrs) noexcept;
[[nodiscard]] bool is_additional_info_mrs(uint8_t mrs) noexcept;

struct Request {
  Command command = Command::Reset;
  uint8_t mrs = 0;        // memory range select (unused by 0x00/0x01)
  uint8_t block = 0;      // block number (0x06/0x07)
  uint8_t parameter = 0;  // parameter number (0x04..0x07)
  uint16_t value = 0;     // value to write (0x05/0x07)

  static constexpr Request reset() noexcept { return {Command::Reset}; }
  static constexpr Request acknowledge() noexcept { return {Command::AcknowledgeErrors}; }
  static constexpr Request read(uint8_t mrs, uint8_t parameter) noexcept {
    return {Command::ReadParameter, mrs, 0, parameter, 0};
  }
  static constexpr Request write(uint8_t mrs, uint8_t parameter, uint16_t value) noexcept {
    return {Command::WriteParameter, mrs, 0, parameter, value};
  }
  static constexpr Request read_block(uint8_t mrs, uint8_t block, uint8_t parameter) noexcept {
    return {Command::ReadBlockParameter, mrs, block, parameter, 0};
  }
  static constexpr Request write_block(uint8_t mrs, uint8_t block, uint8_t parameter,
                                       uint16_t value) noexcept {
    return {Command::WriteBlockParameter, mrs, block, parameter, value};
  }
  // word = 1..4 (which additional-information word to return).
  static constexpr Request read_info(unsigned word, uint8_t mrs) noexcept {
    return {static_cast<Command>(0x08 + ((word - 1) & 3u)), mrs, 0, 0, 0};
  }

  // Fields that do not belong to the command compare as equal.
  [[nodiscard]] bool same_as(const Request& other) const noexcept;
};

// Fixed-capacity byte message (no heap).
template <std::size_t N>
struct Message {
  std::array<uint8_t, N> bytes{};
  uint8_t size = 0;
  [[nodiscard]] std::span<const uint8_t> span() const noexcept { return {bytes.data(), size}; }
  void push(uint8_t b) noexcept {
    if (size < N) bytes[size++] = b;
  }
};
using RequestMessage = Message<kMaxRequestBytes>;
using ReplyMessage = Message<kMaxReplyBytes>;

// Checks a request against the encoder's command set and the command's MRS range.
// Errors: requires_endat22, invalid_mrs, unknown_command.
[[nodiscard]] std::error_code validate(const Request& request, CommandSet encoder) noexcept;

// Master side: the Flatstream message for `request`. Validates first.
[[nodiscard]] Result<RequestMessage> encode_request(const Request& request,
                                                    CommandSet encoder) noexcept;

// Module side: strict parse of a received message. Errors: truncated_request (also for an
// empty message), unknown_command, oversized_request. Does not check the MRS range: the
// encoder answers (or not) for codes the master chose.
[[nodiscard]] Result<Request> decode_request(std::span<const uint8_t> message) noexcept;

// A successful reply.
struct Reply {
  Request echo;                     // command, MRS, block, parameter as echoed
  std::array<uint16_t, 4> words{};  // read value(s): [0] for 0x04/0x06, info words 1..n
  uint8_t word_count = 0;
  // The value asked for: the read parameter or the last (requested) information word.
  [[nodiscard]] uint16_t value() const noexcept {
    return word_count == 0 ? 0 : words[word_count - 1u];
  }
};

// Master side: strict decode of the module's reply to `request`. Errors: truncated_reply,
// oversized_reply, command/mrs/block/parameter_echo_mismatch, module_* (failure replies),
// truncated_failure_reply, oversized_failure_reply.
[[nodiscard]] Result<Reply> decode_reply(const Request& request,
                                         std::span<const uint8_t> message) noexcept;

// Module side: the reply message for a successful command. `words` supplies the read value
// (0x04/0x06: words[0]) or the information words 1..n (0x08..0x0B).
[[nodiscard]] ReplyMessage encode_reply(const Request& request,
                                        std::span<const uint16_t> words = {}) noexcept;

// Why the module-side transaction failed (second byte of a failure reply).
enum class FailureReason : uint8_t {
  CrcError = 1,          // CRC wrong on every retry; the module also sets EnDatComError
  NoResponse = 2,        // the encoder sent no start bit
  NotSupported = 3,      // EnDat 2.2 command, encoder speaks 2.1
  MalformedRequest = 4,  // the request message could not be parsed
  WireEchoMismatch = 5,  // the encoder echoed another address/value on every retry
};
[[nodiscard]] std::string_view failure_reason_name(FailureReason r) noexcept;

// Module side: failure reply for a request whose first byte was `command_byte`.
[[nodiscard]] ReplyMessage encode_failure_reply(uint8_t command_byte,
                                                FailureReason reason) noexcept;

// Daemon side of "write, then read back": success when the read-back equals the written value.
[[nodiscard]] std::error_code check_readback(uint16_t written, uint16_t read_back) noexcept;

}  // namespace ds1928::endat
