// The endat-* socket commands: argument parsing, privilege check, reply formatting. The command
// engine itself is in endat_service.cpp.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <optional>
#include <string>

#include "endat/names.hpp"
#include "endat/number.hpp"
#include "endat_service.hpp"

namespace ds1928 {

namespace {

using endat::Request;
using nlohmann::json;

[[nodiscard]] std::string hex(uint64_t v, int digits) {
  char buf[24];
  std::snprintf(buf, sizeof(buf), "0x%0*llX", digits, static_cast<unsigned long long>(v));
  return buf;
}

// A number argument: a JSON number, or a string in decimal or 0x hex ("0xA9").
[[nodiscard]] uint64_t number_arg(const control::Request& req, const char* name, uint64_t min,
                                  uint64_t max) {
  const json& body = req.body();
  const auto it = body.find(name);
  uint64_t v = 0;
  if (it != body.end() && it->is_string()) {
    auto r = endat::parse_number(it->get<std::string>(), min, max);
    if (!r)
      throw control::ArgumentError("argument '" + std::string(name) + "': '" +
                                   it->get<std::string>() + "': " + r.error().message());
    v = *r;
  } else {
    v = req.get_uint(name, max);
  }
  if (v < min || v > max)
    throw control::ArgumentError("argument '" + std::string(name) + "': " + std::to_string(v) +
                                 " is outside " + std::to_string(min) + ".." + std::to_string(max));
  return v;
}

// The number of parameter words of a memory area where the EnDat specification gives it (the
// manufacturer pages 16 words each, the operating status 4, the EnDat 2.2 manufacturer area 64);
// 256 (the whole 8-bit address) for the areas whose size is the encoder's own.
[[nodiscard]] unsigned known_area_words(uint8_t mrs) noexcept {
  switch (mrs) {
    case 0xA1:
    case 0xA3:
    case 0xA5:
      return 16;
    case 0xB9:
      return 4;
    case 0xBD:
      return 64;
    default:
      return 256;
  }
}

// A parameter number of memory area `mrs`: beyond the area's end is a range error, not a
// command sent to the encoder (which would answer nothing, or another area's word).
[[nodiscard]] uint8_t param_arg(const control::Request& req, uint8_t mrs) {
  const auto param = number_arg(req, "param", 0, 0xFF);
  const unsigned words = known_area_words(mrs);
  if (param >= words) {
    std::string area = hex(mrs, 2);
    if (const auto name = endat::mrs_name(mrs); !name.empty())
      area += " (" + std::string(name) + ")";
    throw control::ArgumentError("argument 'param': " + std::to_string(param) + " is outside MRS " +
                                 area + ": its parameters are 0.." + std::to_string(words - 1));
  }
  return static_cast<uint8_t>(param);
}

// The axis argument, named against the configured axes ("axis 1 does not exist; the axes are
// 0 (x)") rather than as a bare number range.
[[nodiscard]] std::size_t axis_arg(const control::Request& req, const DaemonConfig& config,
                                   std::size_t count) {
  if (count == 0) throw control::ArgumentError("argument 'axis': the daemon has no axes");
  if (!req.has("axis")) return 0;
  const auto axis = number_arg(req, "axis", 0, 0xFFFF);
  if (axis < count) return static_cast<std::size_t>(axis);
  std::string list;
  for (std::size_t i = 0; i < count; ++i) {
    list += (i == 0 ? "" : ", ") + std::to_string(i);
    if (i < config.axes.size() && !config.axes[i].name.empty())
      list += " (" + config.axes[i].name + ")";
  }
  throw control::ArgumentError("argument 'axis': axis " + std::to_string(axis) +
                               " does not exist; the configured " +
                               (count == 1 ? "axis is " : "axes are ") + list);
}

[[nodiscard]] json area_json(uint8_t mrs) {
  json j{{"mrs", mrs}, {"mrs_hex", hex(mrs, 2)}};
  if (const auto name = endat::mrs_name(mrs); !name.empty()) j["area"] = std::string(name);
  return j;
}

[[nodiscard]] json value_json(uint8_t mrs, uint8_t param, uint16_t value) {
  json j{{"value", value}, {"value_hex", hex(value, 4)}};
  if (auto meaning = endat::describe_word(mrs, param, value); !meaning.empty())
    j["meaning"] = std::move(meaning);
  return j;
}

// The reply of the parameter and block commands: area, parameter (and block), the value the
// last step read, and whether it was a verified write.
[[nodiscard]] json param_reply(const char* command, uint8_t mrs, uint8_t param,
                               const EnDatService::JobResult& r, bool verified,
                               std::optional<uint8_t> block = std::nullopt) {
  json j = area_json(mrs);
  j["command"] = command;
  if (block) j["block"] = *block;
  j["param"] = param;
  j.update(value_json(mrs, param, r.steps.back().reply.value()));
  if (verified) j["verified"] = true;
  return j;
}

[[nodiscard]] std::string step_context(const Request& r) {
  std::string s = std::string(endat::command_name(r.command));
  if (endat::has_mrs(r.command)) s += " MRS " + hex(r.mrs, 2);
  if (endat::has_block(r.command)) s += " block " + std::to_string(r.block);
  if (endat::has_parameter(r.command)) s += " parameter " + std::to_string(r.parameter);
  return s;
}

void reply_error(const control::Reply& reply, const EnDatService::JobResult& r) {
  std::string message;
  if (!r.detail.empty()) {
    message = r.detail;
  } else {
    message = r.error.message();
    for (const auto& s : r.steps) {
      if (s.error == r.error) {
        message = step_context(s.request) + ": " + message;
        break;
      }
    }
  }
  reply.error(endat_error_code_name(r.error), std::move(message));
}

// Dump sizes: the operating status has 4 words, the EnDat 2.2 manufacturer area 64.
[[nodiscard]] unsigned area_words(uint8_t mrs) noexcept {
  if (mrs == 0xB9) return 4;
  if (mrs == 0xBD) return 64;
  return 16;
}

}  // namespace

void EnDatService::register_commands(control::Server& server) {
  // Runs a job for a socket request and completes the reply with `format` or the error.
  auto run = [this](const control::Request& req, const control::Reply& reply, JobKind kind,
                    std::vector<Request> steps, std::function<json(const JobResult&)> format) {
    const std::size_t axis = axis_arg(req, config_, axes_.size());
    const JobId id = submit(axis, kind, std::move(steps),
                            [reply, axis, format = std::move(format)](const JobResult& r) {
                              if (r.error) return reply_error(reply, r);
                              json j = format(r);
                              j["axis"] = axis;
                              reply.ok(std::move(j));
                            });
    if (id != 0) {
      reply.on_cancel([this, id, alive = std::weak_ptr<bool>(alive_)] {
        if (!alive.expired()) cancel(id);
      });
    }
  };
  auto privileged = [this](const control::Request& req, const control::Reply& reply) {
    if (may_change_encoder(req)) return true;
    reply.error("permission_denied", "'" + req.command() +
                                         "' changes the encoder: needs uid 0 or group '" +
                                         config_.socket.privileged_group + "'");
    return false;
  };

  server.add_command("endat-reset",
                     [run, privileged](const control::Request& req, control::Reply reply) {
                       if (!privileged(req, reply)) return;
                       run(req, reply, JobKind::Single, {Request::reset()}, [](const JobResult&) {
                         return json{{"command", "reset"}};
                       });
                     });

  // Acknowledging clears the encoder's error and warning bits for every client: privileged.
  server.add_command(
      "endat-ack", [run, privileged](const control::Request& req, control::Reply reply) {
        if (!privileged(req, reply)) return;
        run(req, reply, JobKind::Single, {Request::acknowledge()}, [](const JobResult&) {
          return json{{"command", "ack"}};
        });
      });

  server.add_command("endat-read-param", [run](const control::Request& req, control::Reply reply) {
    const auto mrs = static_cast<uint8_t>(number_arg(req, "mrs", 0, 0xFF));
    const uint8_t param = param_arg(req, mrs);
    run(req, reply, JobKind::Single, {Request::read(mrs, param)}, [mrs, param](const JobResult& r) {
      return param_reply("read-param", mrs, param, r, false);
    });
  });

  server.add_command(
      "endat-write-param", [run, privileged](const control::Request& req, control::Reply reply) {
        const auto mrs = static_cast<uint8_t>(number_arg(req, "mrs", 0, 0xFF));
        const uint8_t param = param_arg(req, mrs);
        const auto value = static_cast<uint16_t>(number_arg(req, "value", 0, 0xFFFF));
        if (!privileged(req, reply)) return;
        run(req, reply, JobKind::WriteVerify,
            {Request::write(mrs, param, value), Request::read(mrs, param)},
            [mrs, param](const JobResult& r) {
              return param_reply("write-param", mrs, param, r, true);
            });
      });

  server.add_command("endat-read-block", [run](const control::Request& req, control::Reply reply) {
    const auto mrs = static_cast<uint8_t>(number_arg(req, "mrs", 0, 0xFF));
    const auto block = static_cast<uint8_t>(number_arg(req, "block", 0, 0xFF));
    const auto param = static_cast<uint8_t>(number_arg(req, "param", 0, 0xFF));
    run(req, reply, JobKind::Single, {Request::read_block(mrs, block, param)},
        [mrs, block, param](const JobResult& r) {
          return param_reply("read-block", mrs, param, r, false, block);
        });
  });

  server.add_command("endat-write-block", [run, privileged](const control::Request& req,
                                                            control::Reply reply) {
    const auto mrs = static_cast<uint8_t>(number_arg(req, "mrs", 0, 0xFF));
    const auto block = static_cast<uint8_t>(number_arg(req, "block", 0, 0xFF));
    const auto param = static_cast<uint8_t>(number_arg(req, "param", 0, 0xFF));
    const auto value = static_cast<uint16_t>(number_arg(req, "value", 0, 0xFFFF));
    if (!privileged(req, reply)) return;
    run(req, reply, JobKind::WriteVerify,
        {Request::write_block(mrs, block, param, value), Request::read_block(mrs, block, param)},
        [mrs, block, param](const JobResult& r) {
          return param_reply("write-block", mrs, param, r, true, block);
        });
  });

  server.add_command("endat-read-info", [run](const control::Request& req, control::Reply reply) {
    const auto word = static_cast<unsigned>(number_arg(req, "word", 1, 4));
    const auto mrs = static_cast<uint8_t>(number_arg(req, "mrs", 0, 0xFF));
    run(req, reply, JobKind::Single, {Request::read_info(word, mrs)},
        [word, mrs](const JobResult& r) {
          const endat::Reply& rep = r.steps.back().reply;
          json j{{"command", "read-info"}, {"word", word}, {"mrs", mrs}, {"mrs_hex", hex(mrs, 2)}};
          if (const auto name = endat::mrs_name(mrs); !name.empty()) j["info"] = std::string(name);
          j.update(value_json(mrs, 0, rep.value()));
          json words = json::array();
          for (unsigned i = 0; i < rep.word_count; ++i) words.push_back(rep.words[i]);
          j["words"] = std::move(words);
          return j;
        });
  });

  server.add_command("endat-dump", [run](const control::Request& req, control::Reply reply) {
    const auto mrs = static_cast<uint8_t>(number_arg(req, "mrs", 0, 0xFF));
    const unsigned count =
        req.has("count") ? static_cast<unsigned>(number_arg(req, "count", 1, 64)) : area_words(mrs);
    std::vector<Request> steps;
    for (unsigned p = 0; p < count; ++p)
      steps.push_back(Request::read(mrs, static_cast<uint8_t>(p)));
    run(req, reply, JobKind::Sequence, std::move(steps), [mrs, count](const JobResult& r) {
      json j = area_json(mrs);
      j["command"] = "dump";
      j["count"] = count;
      json words = json::array();
      for (const auto& s : r.steps) {
        json w{{"param", s.request.parameter}};
        if (s.error) {
          w["error"] = {{"code", std::string(endat_error_code_name(s.error))},
                        {"message", s.error.message()}};
        } else {
          w.update(value_json(mrs, s.request.parameter, s.reply.value()));
        }
        words.push_back(std::move(w));
      }
      j["words"] = std::move(words);
      return j;
    });
  });

  server.add_command("endat-ident", [this](const control::Request& req, control::Reply reply) {
    const std::size_t axis = axis_arg(req, config_, axes_.size());
    const bool refresh = req.opt_bool("refresh").value_or(false);
    auto answer = [this, axis, reply, alive = std::weak_ptr<bool>(alive_)](std::error_code ec) {
      if (alive.expired()) return;
      if (!identification(axis)) {
        const auto error = ec ? ec : make_error_code(EnDatServiceErrc::identification_unavailable);
        return reply.error(endat_error_code_name(error),
                           "axis " + std::to_string(axis) + ": identification: " + error.message());
      }
      reply.ok(identification_reply(axis));
    };
    if (!refresh && identification(axis) && !identifying(axis)) return answer({});
    if (!refresh) return refresh_identification(axis, std::move(answer));
    // A refresh first makes the module read the encoder's identification again (Rescan), so the
    // registers are the encoder's of now, not of the last power-up.
    endat_ack_register(
        axis, kEnDatAckRescan,
        [this, axis, answer = std::move(answer), alive = std::weak_ptr<bool>(alive_)](
            std::error_code ec, bool, unsigned) mutable {
          if (alive.expired()) return;
          if (ec) spdlog::warn("axis {}: Rescan before the identification: {}", axis, ec.message());
          refresh_identification(axis, std::move(answer));
        });
  });

  // EnDatAck through the module register (§11.6.2.3): bit 1 Rescan, bit 0 acknowledge. Both
  // change what every client sees: privileged.
  auto endat_ack_command = [this, privileged](const char* name, uint8_t bits) {
    return [this, privileged, name, bits](const control::Request& req, control::Reply reply) {
      if (!privileged(req, reply)) return;
      if (axes_.empty()) throw control::ArgumentError("argument 'axis': the daemon has no axes");
      const auto axis = static_cast<std::size_t>(
          req.has("axis") ? number_arg(req, "axis", 0, axes_.size() - 1) : 0);
      const auto started = std::chrono::steady_clock::now();
      endat_ack_register(
          axis, bits,
          [this, axis, reply, name, bits, started, alive = std::weak_ptr<bool>(alive_)](
              std::error_code ec, bool confirmed, unsigned reads) {
            if (alive.expired()) return;
            if (ec)
              return reply.error(
                  endat_error_code_name(ec),
                  "axis " + std::to_string(axis) + ": EnDatAck " + name + ": " + ec.message());
            const auto waited = std::chrono::duration_cast<std::chrono::microseconds>(
                std::chrono::steady_clock::now() - started);
            // After a Rescan the identification is read again (and compared with
            // axes[].expected_encoder).
            if ((bits & kEnDatAckRescan) != 0) refresh_identification(axis, nullptr);
            reply.ok({{"axis", axis},
                      {"command", name},
                      {"register", "EnDatAck"},
                      {"bits", bits},
                      {"confirmed", confirmed},
                      {"reads", reads},
                      {"wait_ms", static_cast<double>(waited.count()) / 1000.0}});
          });
    };
  };
  server.add_command("endat-rescan", endat_ack_command("rescan", kEnDatAckRescan));
  server.add_command("endat-ack-register", endat_ack_command("ack", kEnDatAckAcknowledge));
}

}  // namespace ds1928
