#include "powerlink_commands.hpp"

#include <array>
#include <nlohmann/json.hpp>
#include <vector>

#include "core/clock.hpp"
#include "endat_service.hpp"
#include "powerlink/powerlink_bus.hpp"

namespace ds1928 {
namespace {

using powerlink::MnError;
using powerlink::PowerlinkBus;

std::string to_hex(std::span<const uint8_t> bytes) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string s;
  s.reserve(bytes.size() * 2);
  for (uint8_t b : bytes) {
    s.push_back(kDigits[b >> 4]);
    s.push_back(kDigits[b & 0xF]);
  }
  return s;
}

int hex_digit(char c) noexcept {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// "0a1B..." → bytes; throws ArgumentError naming what is wrong.
std::vector<uint8_t> parse_hex(const std::string& s) {
  if (s.size() % 2 != 0)
    throw control::ArgumentError("argument 'hex': odd number of hex digits (" +
                                 std::to_string(s.size()) + ")");
  if (s.size() / 2 > powerlink::kMaxPreqWrite)
    throw control::ArgumentError("argument 'hex': " + std::to_string(s.size() / 2) +
                                 " bytes, at most " + std::to_string(powerlink::kMaxPreqWrite) +
                                 " per request");
  std::vector<uint8_t> out(s.size() / 2);
  for (std::size_t i = 0; i < out.size(); ++i) {
    const int hi = hex_digit(s[2 * i]);
    const int lo = hex_digit(s[2 * i + 1]);
    if (hi < 0 || lo < 0)
      throw control::ArgumentError("argument 'hex': '" + s.substr(2 * i, 2) + "' at byte " +
                                   std::to_string(i) + " is not hex");
    out[i] = static_cast<uint8_t>(hi << 4 | lo);
  }
  return out;
}

}  // namespace

void register_powerlink_commands(control::Server& server, PowerlinkBus& bus,
                                 std::string privileged_group) {
  using control::Reply;
  using control::Request;
  PowerlinkBus* pl = &bus;

  server.add_command("pl-pres", [pl](const Request& req, Reply reply) {
    const auto node = static_cast<uint8_t>(req.get_uint("node", 255));
    // A snapshot is ~1.5 kB per CN: on the heap, not on the handler's stack.
    auto snap = std::make_unique<powerlink::PresSnapshot>();
    if (!pl->pres_snapshot(node, *snap))
      throw control::ArgumentError("argument 'node': " + std::to_string(node) +
                                   " is not a configured POWERLINK CN");
    nlohmann::json j{
        {"node", node}, {"size", snap->size}, {"fresh", snap->fresh}, {"ready", snap->ready}};
    if (snap->received) {
      j["age_us"] = (rt::now_ns() - snap->rx_time_ns) / 1000;
      j["cycle"] = snap->cycle;
    } else {
      j["age_us"] = nullptr;  // no PRes yet
    }
    j["hex"] = to_hex(snap->bytes());
    reply.ok(std::move(j));
  });

  server.add_command("pl-preq-set", [pl, group = std::move(privileged_group)](const Request& req,
                                                                              Reply reply) {
    if (!control::peer_is_privileged(req.peer(), group))
      return reply.error(
          "permission_denied",
          "'pl-preq-set' changes the process outputs: needs uid 0 or group '" + group + "'");
    const auto node = static_cast<uint8_t>(req.get_uint("node", 255));
    const auto offset = static_cast<uint16_t>(req.get_uint("offset", powerlink::kMaxIsoPayload));
    const std::vector<uint8_t> bytes = parse_hex(req.get_string("hex"));
    const powerlink::PreqWriteCheck c = pl->set_preq(node, offset, bytes);
    const std::string where = "node " + std::to_string(node);
    if (c.error == MnError::kNodeNotConfigured)
      throw control::ArgumentError("argument 'node': " + std::to_string(node) +
                                   " is not a configured POWERLINK CN");
    if (c.error == MnError::kPreqOutOfRange)
      return reply.error("preq_out_of_range",
                         "offset " + std::to_string(offset) + " + " + std::to_string(bytes.size()) +
                             " bytes runs past the PReq of " + where + " (" +
                             std::to_string(c.preq_size) + " bytes" +
                             (c.preq_size == 0 ? ", CN not identified yet)" : ")"));
    if (c.error == MnError::kPreqRegionOwnedByModule) {
      const std::size_t end = powerlink::preq_end(c.module);
      return reply.error(
          "preq_module_region",
          "bytes " + std::to_string(offset) + ".." + std::to_string(offset + bytes.size() - 1) +
              " of the PReq of " + where + " overlap the X20DS1928 in slot " +
              std::to_string(c.module.slot) + " (bytes " + std::to_string(c.module.preq_offset) +
              ".." + std::to_string(end - 1) + "), which belong to its axis");
    }
    if (c.error == MnError::kQueueFull) return reply.error("busy", "PReq write queue full; retry");
    if (c.error) return reply.error("internal", c.error.message());
    reply.ok(
        {{"node", node}, {"offset", offset}, {"size", bytes.size()}, {"preq_size", c.preq_size}});
  });
}

}  // namespace ds1928
