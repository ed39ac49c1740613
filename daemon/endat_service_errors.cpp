#include <cstdio>

#include "endat_service_state.hpp"

namespace ds1928 {

// ---------------------------------------------------------------------------------------------
// Errors

namespace {

class ServiceCategory final : public std::error_category {
 public:
  [[nodiscard]] const char* name() const noexcept override { return "endat-service"; }
  [[nodiscard]] std::string message(int c) const override {
    switch (static_cast<EnDatServiceErrc>(c)) {
      case EnDatServiceErrc::timeout:
        return "no reply from the module within the command timeout";
      case EnDatServiceErrc::not_delivered:
        return "the command did not reach the module (not executed)";
      case EnDatServiceErrc::busy:
        return "the axis' EnDat command queue is full";
      case EnDatServiceErrc::write_rejected:
        return "the value read back differs from the value written (write-protected area?)";
      case EnDatServiceErrc::cancelled:
        return "cancelled: the client went away";
      case EnDatServiceErrc::stopped:
        return "the daemon is stopping";
      case EnDatServiceErrc::no_such_axis:
        return "no such axis";
      case EnDatServiceErrc::identification_unavailable:
        return "the encoder identification could not be read";
    }
    return "unknown EnDat service error";
  }
};

}  // namespace

const std::error_category& endat_service_category() noexcept {
  static const ServiceCategory category;
  return category;
}

std::error_code make_error_code(EnDatServiceErrc e) noexcept {
  return {static_cast<int>(e), endat_service_category()};
}

std::string_view endat_error_code_name(std::error_code ec) noexcept {
  if (!ec) return "ok";
  if (ec.category() == endat_service_category()) {
    switch (static_cast<EnDatServiceErrc>(ec.value())) {
      case EnDatServiceErrc::timeout:
        return "timeout";
      case EnDatServiceErrc::not_delivered:
        return "not_delivered";
      case EnDatServiceErrc::busy:
        return "busy";
      case EnDatServiceErrc::write_rejected:
        return "write_rejected";
      case EnDatServiceErrc::cancelled:
        return "cancelled";
      case EnDatServiceErrc::stopped:
        return "stopped";
      case EnDatServiceErrc::no_such_axis:
        return "bad_argument";
      case EnDatServiceErrc::identification_unavailable:
        return "identification_unavailable";
    }
    return "internal";
  }
  if (ec.category() == endat::error_category()) {
    using endat::Errc;
    switch (static_cast<Errc>(ec.value())) {
      case Errc::truncated_reply:
      case Errc::truncated_failure_reply:
        return "truncated_reply";
      case Errc::oversized_reply:
      case Errc::oversized_failure_reply:
        return "oversized_reply";
      case Errc::command_echo_mismatch:
      case Errc::mrs_echo_mismatch:
      case Errc::block_echo_mismatch:
      case Errc::parameter_echo_mismatch:
        return "echo_mismatch";
      case Errc::requires_endat22:
        return "requires_endat22";
      case Errc::invalid_mrs:
      case Errc::unknown_command:
      case Errc::invalid_number:
      case Errc::number_out_of_range:
        return "bad_argument";
      case Errc::module_crc_failure:
        return "module_crc_error";
      case Errc::module_no_response:
        return "module_no_response";
      case Errc::module_not_supported:
        return "module_not_supported";
      case Errc::module_malformed_request:
        return "module_malformed_request";
      case Errc::module_wire_echo_mismatch:
        return "module_wire_echo_mismatch";
      case Errc::module_unknown_failure:
        return "module_failure";
      case Errc::write_not_applied:
        return "write_rejected";
      case Errc::invalid_identification:
        return "invalid_identification";
      default:
        return "internal";
    }
  }
  return "internal";
}

}  // namespace ds1928
