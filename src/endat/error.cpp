#include "endat/error.hpp"

#include <string>

namespace ds1928::endat {
namespace {

class Category final : public std::error_category {
 public:
  const char* name() const noexcept override { return "endat"; }

  std::string message(int code) const override {
    switch (static_cast<Errc>(code)) {
      case Errc::truncated_reply:
        return "reply shorter than the command's reply format";
      case Errc::oversized_reply:
        return "reply longer than the command's reply format";
      case Errc::command_echo_mismatch:
        return "reply does not echo the command byte";
      case Errc::mrs_echo_mismatch:
        return "reply echoes a different MRS code";
      case Errc::block_echo_mismatch:
        return "reply echoes a different block number";
      case Errc::parameter_echo_mismatch:
        return "reply echoes a different parameter number";
      case Errc::unknown_command:
        return "unknown EnDat module command";
      case Errc::requires_endat22:
        return "command needs an EnDat 2.2 encoder; the encoder supports only EnDat 2.1";
      case Errc::invalid_mrs:
        return "MRS code not valid for this command";
      case Errc::truncated_request:
        return "request shorter than the command's format";
      case Errc::oversized_request:
        return "request longer than the command's format";
      case Errc::module_crc_failure:
        return "module reports EnDat CRC errors on every retry (communication error)";
      case Errc::module_no_response:
        return "module reports no answer from the encoder";
      case Errc::module_not_supported:
        return "module reports the encoder does not support it";
      case Errc::module_malformed_request:
        return "module could not parse the request";
      case Errc::module_wire_echo_mismatch:
        return "module reports a wrong address echo from the encoder";
      case Errc::module_unknown_failure:
        return "module reports a failure of unknown reason";
      case Errc::truncated_failure_reply:
        return "failure reply without its reason byte";
      case Errc::oversized_failure_reply:
        return "failure reply longer than two bytes";
      case Errc::write_not_applied:
        return "value read back differs from the value written (write-protected area?)";
      case Errc::no_response:
        return "no start bit: the encoder did not answer";
      case Errc::crc_mismatch:
        return "EnDat CRC mismatch";
      case Errc::frame_length:
        return "EnDat frame has the wrong number of bits";
      case Errc::invalid_mode:
        return "not an EnDat mode command";
      case Errc::f2_not_inverted:
        return "EnDat 2.2 position frame: F2 is not the inverse of F1";
      case Errc::invalid_identification:
        return "encoder identification words are inconsistent";
      case Errc::invalid_number:
        return "not a number (decimal or 0x-prefixed hex expected)";
      case Errc::number_out_of_range:
        return "number out of range";
    }
    return "unknown endat error " + std::to_string(code);
  }

  bool equivalent(int code, const std::error_condition& cond) const noexcept override {
    if (cond.category() != condition_category()) return false;
    const auto e = static_cast<Errc>(code);
    switch (static_cast<Condition>(cond.value())) {
      case Condition::echo_mismatch:
        return e == Errc::command_echo_mismatch || e == Errc::mrs_echo_mismatch ||
               e == Errc::block_echo_mismatch || e == Errc::parameter_echo_mismatch;
      case Condition::module_failure:
        return e == Errc::module_crc_failure || e == Errc::module_no_response ||
               e == Errc::module_not_supported || e == Errc::module_malformed_request ||
               e == Errc::module_wire_echo_mismatch || e == Errc::module_unknown_failure;
      case Condition::malformed_reply:
        return e == Errc::truncated_reply || e == Errc::oversized_reply ||
               e == Errc::command_echo_mismatch || e == Errc::mrs_echo_mismatch ||
               e == Errc::block_echo_mismatch || e == Errc::parameter_echo_mismatch ||
               e == Errc::truncated_failure_reply || e == Errc::oversized_failure_reply;
      case Condition::bad_request:
        return e == Errc::unknown_command || e == Errc::requires_endat22 ||
               e == Errc::invalid_mrs || e == Errc::truncated_request ||
               e == Errc::oversized_request;
    }
    return false;
  }
};

class ConditionCategory final : public std::error_category {
 public:
  const char* name() const noexcept override { return "endat-condition"; }
  std::string message(int c) const override {
    switch (static_cast<Condition>(c)) {
      case Condition::echo_mismatch:
        return "reply echo does not match the request";
      case Condition::module_failure:
        return "module reported a failed EnDat transaction";
      case Condition::malformed_reply:
        return "malformed reply";
      case Condition::bad_request:
        return "request cannot be sent";
    }
    return "unknown endat condition " + std::to_string(c);
  }
};

}  // namespace

const std::error_category& error_category() noexcept {
  static const Category category;
  return category;
}

const std::error_category& condition_category() noexcept {
  static const ConditionCategory category;
  return category;
}

}  // namespace ds1928::endat
