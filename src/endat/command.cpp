#include "endat/command.hpp"

namespace ds1928::endat {

std::optional<Command> command_from_byte(uint8_t byte) noexcept {
  if (byte == 0x00 || byte == 0x01 || (byte >= 0x04 && byte <= 0x0B)) {
    return static_cast<Command>(byte);
  }
  return std::nullopt;
}

std::string_view command_name(Command c) noexcept {
  switch (c) {
    case Command::Reset:
      return "reset";
    case Command::AcknowledgeErrors:
      return "acknowledge errors";
    case Command::ReadParameter:
      return "read parameter";
    case Command::WriteParameter:
      return "write parameter";
    case Command::ReadBlockParameter:
      return "read parameter from memory block";
    case Command::WriteBlockParameter:
      return "write parameter to memory block";
    case Command::ReadInfoWord1:
      return "read word 1 of additional information";
    case Command::ReadInfoWord2:
      return "read word 2 of additional information";
    case Command::ReadInfoWord3:
      return "read word 3 of additional information";
    case Command::ReadInfoWord4:
      return "read word 4 of additional information";
  }
  return "?";
}

bool requires_endat22(Command c) noexcept {
  return static_cast<uint8_t>(c) >= 0x06;
}

bool has_mrs(Command c) noexcept {
  return static_cast<uint8_t>(c) >= 0x04;
}

bool has_block(Command c) noexcept {
  return c == Command::ReadBlockParameter || c == Command::WriteBlockParameter;
}

bool has_parameter(Command c) noexcept {
  const auto b = static_cast<uint8_t>(c);
  return b >= 0x04 && b <= 0x07;
}

bool is_write(Command c) noexcept {
  return c == Command::WriteParameter || c == Command::WriteBlockParameter;
}

bool is_info_read(Command c) noexcept {
  return static_cast<uint8_t>(c) >= 0x08;
}

unsigned info_word_count(Command c) noexcept {
  return is_info_read(c) ? static_cast<unsigned>(static_cast<uint8_t>(c) - 0x07) : 0u;
}

std::size_t request_size(Command c) noexcept {
  switch (c) {
    case Command::Reset:
    case Command::AcknowledgeErrors:
      return 1;
    case Command::ReadParameter:
      return 3;
    case Command::WriteParameter:
      return 5;
    case Command::ReadBlockParameter:
      return 4;
    case Command::WriteBlockParameter:
      return 6;
    case Command::ReadInfoWord1:
    case Command::ReadInfoWord2:
    case Command::ReadInfoWord3:
    case Command::ReadInfoWord4:
      return 2;
  }
  return 0;
}

std::size_t reply_size(Command c) noexcept {
  switch (c) {
    case Command::Reset:
    case Command::AcknowledgeErrors:
      return 1;
    case Command::ReadParameter:
      return 5;
    case Command::WriteParameter:
      return 3;
    case Command::ReadBlockParameter:
      return 6;
    case Command::WriteBlockParameter:
      return 4;
    case Command::ReadInfoWord1:
    case Command::ReadInfoWord2:
    case Command::ReadInfoWord3:
    case Command::ReadInfoWord4:
      return 2 + 2 * info_word_count(c);
  }
  return 0;
}

bool is_memory_area_mrs(uint8_t mrs) noexcept {
  return mrs >= 0xA0 && mrs <= 0xBF;
}
bool is_additional_info_mrs(uint8_t mrs) noexcept {
  return mrs >= 0x40 && mrs <= 0x5F;
}

bool Request::same_as(const Request& other) const noexcept {
  if (command != other.command) return false;
  if (has_mrs(command) && mrs != other.mrs) return false;
  if (has_block(command) && block != other.block) return false;
  if (has_parameter(command) && parameter != other.parameter) return false;
  if (is_write(command) && value != other.value) return false;
  return true;
}

std::error_code validate(const Request& request, CommandSet encoder) noexcept {
  if (!command_from_byte(static_cast<uint8_t>(request.command))) return Errc::unknown_command;
  if (requires_endat22(request.command) && encoder != CommandSet::EnDat22) {
    return Errc::requires_endat22;
  }
  if (is_info_read(request.command)) {
    if (!is_additional_info_mrs(request.mrs)) return Errc::invalid_mrs;
  } else if (has_mrs(request.command) && !is_memory_area_mrs(request.mrs)) {
    return Errc::invalid_mrs;
  }
  return {};
}

Result<RequestMessage> encode_request(const Request& request, CommandSet encoder) noexcept {
  if (auto ec = validate(request, encoder)) return ec;
  RequestMessage m;
  const Command c = request.command;
  m.push(static_cast<uint8_t>(c));
  if (has_mrs(c)) m.push(request.mrs);
  if (has_block(c)) m.push(request.block);
  if (has_parameter(c)) m.push(request.parameter);
  if (is_write(c)) {
    m.push(static_cast<uint8_t>(request.value & 0xFF));
    m.push(static_cast<uint8_t>(request.value >> 8));
  }
  return m;
}

Result<Request> decode_request(std::span<const uint8_t> message) noexcept {
  if (message.empty()) return Errc::truncated_request;
  const auto command = command_from_byte(message[0]);
  if (!command) return Errc::unknown_command;
  const std::size_t expected = request_size(*command);
  if (message.size() < expected) return Errc::truncated_request;
  if (message.size() > expected) return Errc::oversized_request;
  Request r;
  r.command = *command;
  std::size_t i = 1;
  if (has_mrs(r.command)) r.mrs = message[i++];
  if (has_block(r.command)) r.block = message[i++];
  if (has_parameter(r.command)) r.parameter = message[i++];
  if (is_write(r.command)) {
    r.value = static_cast<uint16_t>(message[i] | (message[i + 1] << 8));
  }
  return r;
}

Result<Reply> decode_reply(const Request& request, std::span<const uint8_t> message) noexcept {
  if (message.empty()) return Errc::truncated_reply;
  const auto command_byte = static_cast<uint8_t>(request.command);
  if (message[0] == (kFailureMarker | command_byte)) {
    if (message.size() < 2) return Errc::truncated_failure_reply;
    if (message.size() > 2) return Errc::oversized_failure_reply;
    switch (static_cast<FailureReason>(message[1])) {
      case FailureReason::CrcError:
        return Errc::module_crc_failure;
      case FailureReason::NoResponse:
        return Errc::module_no_response;
      case FailureReason::NotSupported:
        return Errc::module_not_supported;
      case FailureReason::MalformedRequest:
        return Errc::module_malformed_request;
      case FailureReason::WireEchoMismatch:
        return Errc::module_wire_echo_mismatch;
    }
    return Errc::module_unknown_failure;
  }
  if (message[0] != command_byte) return Errc::command_echo_mismatch;
  const std::size_t expected = reply_size(request.command);
  if (message.size() < expected) return Errc::truncated_reply;
  if (message.size() > expected) return Errc::oversized_reply;

  Reply reply;
  reply.echo.command = request.command;
  std::size_t i = 1;
  if (has_mrs(request.command)) {
    reply.echo.mrs = message[i++];
    if (reply.echo.mrs != request.mrs) return Errc::mrs_echo_mismatch;
  }
  if (has_block(request.command)) {
    reply.echo.block = message[i++];
    if (reply.echo.block != request.block) return Errc::block_echo_mismatch;
  }
  if (has_parameter(request.command)) {
    reply.echo.parameter = message[i++];
    if (reply.echo.parameter != request.parameter) return Errc::parameter_echo_mismatch;
  }
  if (is_write(request.command)) reply.echo.value = request.value;
  const unsigned words =
      (request.command == Command::ReadParameter || request.command == Command::ReadBlockParameter)
          ? 1u
          : info_word_count(request.command);
  for (unsigned w = 0; w < words; ++w, i += 2) {
    reply.words[w] = static_cast<uint16_t>(message[i] | (message[i + 1] << 8));
  }
  reply.word_count = static_cast<uint8_t>(words);
  return reply;
}

ReplyMessage encode_reply(const Request& request, std::span<const uint16_t> words) noexcept {
  ReplyMessage m;
  const Command c = request.command;
  m.push(static_cast<uint8_t>(c));
  if (has_mrs(c)) m.push(request.mrs);
  if (has_block(c)) m.push(request.block);
  if (has_parameter(c)) m.push(request.parameter);
  const unsigned n =
      (c == Command::ReadParameter || c == Command::ReadBlockParameter) ? 1u : info_word_count(c);
  for (unsigned w = 0; w < n; ++w) {
    const uint16_t v = w < words.size() ? words[w] : 0;
    m.push(static_cast<uint8_t>(v & 0xFF));
    m.push(static_cast<uint8_t>(v >> 8));
  }
  return m;
}

std::string_view failure_reason_name(FailureReason r) noexcept {
  switch (r) {
    case FailureReason::CrcError:
      return "CRC error";
    case FailureReason::NoResponse:
      return "no response";
    case FailureReason::NotSupported:
      return "not supported by the encoder";
    case FailureReason::MalformedRequest:
      return "malformed request";
    case FailureReason::WireEchoMismatch:
      return "wrong echo on the EnDat wire";
  }
  return "unknown";
}

ReplyMessage encode_failure_reply(uint8_t command_byte, FailureReason reason) noexcept {
  ReplyMessage m;
  m.push(static_cast<uint8_t>(kFailureMarker | (command_byte & 0x7F)));
  m.push(static_cast<uint8_t>(reason));
  return m;
}

std::error_code check_readback(uint16_t written, uint16_t read_back) noexcept {
  if (written != read_back) return Errc::write_not_applied;
  return {};
}

}  // namespace ds1928::endat
