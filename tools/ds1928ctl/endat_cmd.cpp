// `ds1928ctl endat ...`: EnDat commands through the daemon (endat-* socket commands).
// Numbers are decimal or 0x hex; human output names the memory area and the decoded meaning,
// --json prints the daemon's reply (raw and decoded values).
#include <cinttypes>
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "client.hpp"
#include "commands.hpp"
#include "endat/number.hpp"

namespace ds1928::ctl {
namespace {

using json = nlohmann::json;

uint64_t num(const json& j, const char* key) {
  const auto it = j.find(key);
  return it != j.end() && it->is_number_unsigned() ? it->get<uint64_t>() : 0;
}

std::string str(const json& j, const char* key) {
  const auto it = j.find(key);
  return it != j.end() && it->is_string() ? it->get<std::string>() : std::string();
}

std::string hex(uint64_t v, int digits) {
  char buf[24];
  std::snprintf(buf, sizeof(buf), "0x%0*" PRIX64, digits, v);
  return buf;
}

// "MRS 0xA9 (OEM parameters, area 1)"
std::string area_text(const json& r) {
  std::string s = "MRS " + hex(num(r, "mrs"), 2);
  if (const auto a = str(r, "area"); !a.empty()) s += " (" + a + ")";
  return s;
}

std::string value_text(const json& r) {
  std::string s = hex(num(r, "value"), 4) + " (" + std::to_string(num(r, "value")) + ")";
  if (const auto m = str(r, "meaning"); !m.empty()) s += ": " + m;
  return s;
}

void print_param(const json& r) {
  std::cout << "axis " << num(r, "axis") << " " << area_text(r);
  if (r.contains("block")) std::cout << " block " << num(r, "block");
  std::cout << " parameter " << num(r, "param") << ": " << value_text(r);
  if (r.value("verified", false)) std::cout << " (written and read back)";
  std::cout << "\n";
}

void print_info(const json& r) {
  std::cout << "axis " << num(r, "axis") << " additional information word " << num(r, "word")
            << " of " << hex(num(r, "mrs"), 2);
  if (const auto i = str(r, "info"); !i.empty()) std::cout << " (" << i << ")";
  std::cout << ": " << hex(num(r, "value"), 4) << " (" << num(r, "value") << ")";
  if (const auto m = str(r, "meaning"); !m.empty()) std::cout << "\n  " << m;
  std::cout << "\n";
}

void print_ident(const json& r) {
  const json id = r.value("identification", json::object());
  std::cout << "axis " << num(r, "axis") << ": EnDat " << str(id, "endat") << " " << str(id, "type")
            << " encoder (identification from " << str(r, "source") << ")\n";
  std::cout << "  ID number:         " << str(id, "id") << "\n";
  std::cout << "  serial number:     " << str(id, "serial") << "\n";
  std::cout << "  position bits:     " << num(id, "position_bits") << "\n";
  if (str(id, "type") == "rotary") {
    std::cout << "  steps/revolution:  " << num(id, "steps_per_revolution") << "\n";
    std::cout << "  revolutions:       "
              << (id.value("multiturn", false) ? std::to_string(num(id, "revolutions"))
                                               : std::string("singleturn"))
              << "\n";
    std::cout << "  signal periods:    " << num(id, "signal_periods") << " per revolution\n";
  } else {
    std::cout << "  signal periods:    " << num(id, "signal_periods") << "\n";
  }
  std::cout << "  version word:      " << str(id, "version_word_hex") << "\n";
  auto names = [](const json& list) {
    std::string s;
    for (const auto& n : list) s += (s.empty() ? "" : ", ") + n.get<std::string>();
    return s.empty() ? std::string("none") : s;
  };
  if (r.contains("endat_error"))
    std::cout << "  EnDat errors:      " << hex(num(r, "endat_error"), 4) << " ("
              << names(r.value("endat_error_names", json::array())) << ")\n";
  if (r.contains("endat_warning"))
    std::cout << "  EnDat warnings:    " << hex(num(r, "endat_warning"), 4) << " ("
              << names(r.value("endat_warning_names", json::array())) << ")\n";
}

void print_dump(const json& r) {
  std::cout << "axis " << num(r, "axis") << " " << area_text(r) << ", " << num(r, "count")
            << " words\n";
  for (const auto& w : r.value("words", json::array())) {
    std::printf("  %3" PRIu64 "  ", num(w, "param"));
    if (w.contains("error")) {
      std::printf("error %s: %s\n", str(w["error"], "code").c_str(),
                  str(w["error"], "message").c_str());
      continue;
    }
    std::printf("%s %6" PRIu64, hex(num(w, "value"), 4).c_str(), num(w, "value"));
    if (const auto m = str(w, "meaning"); !m.empty()) std::printf("  %s", m.c_str());
    std::printf("\n");
  }
}

// A positional number argument checked when the command line is parsed.
struct Number {
  std::string text;
  uint64_t value = 0;
};

CLI::Option* add_number(CLI::App* cmd, const char* name, Number& n, const char* what) {
  return cmd->add_option(name, n.text, what)->required();
}

uint64_t parse(const char* name, const Number& n, uint64_t min, uint64_t max) {
  const auto r = endat::parse_number(n.text, min, max);
  if (!r) throw CLI::ValidationError(name, "'" + n.text + "': " + r.error().message());
  return *r;
}

}  // namespace

void add_endat_commands(CLI::App& app, Context& ctx) {
  auto* endat = app.add_subcommand("endat", "EnDat commands to the encoder (through Flatstream)");
  endat->require_subcommand(1);
  endat->fallthrough();
  auto axis = std::make_shared<Number>();
  axis->text = "0";
  endat->add_option("--axis,-a", axis->text, "Axis index (0-based, default 0)");
  endat->footer(
      "Numbers are decimal or 0x hex. MRS = memory range select (0xA1..0xBF areas, 0x40..0x5F "
      "additional information).\nwrite-param, write-block and reset need uid 0 or the daemon's "
      "privileged group.");

  // Sends `request` (+ axis) once parsing succeeded.
  auto action = [&ctx, axis](json request, HumanPrinter print) {
    request["axis"] = parse("--axis", *axis, 0, 0xFFFF);
    ctx.action = [&ctx, request = std::move(request), print = std::move(print)] {
      return request_and_print(ctx, request, print);
    };
  };

  endat->add_subcommand("reset", "Reset the encoder (EnDat command 0x00)")->callback([action] {
    action({{"cmd", "endat-reset"}},
           [](const json& r) { std::cout << "axis " << num(r, "axis") << ": encoder reset\n"; });
  });
  endat->add_subcommand("ack", "Acknowledge the encoder's errors (EnDat command 0x01)")
      ->callback([action] {
        action({{"cmd", "endat-ack"}}, [](const json& r) {
          std::cout << "axis " << num(r, "axis") << ": encoder errors acknowledged\n";
        });
      });
  {
    // Rescan (EnDatAck bit 1, a module register, not a Flatstream command): the module reads the
    // encoder's identification again; the daemon waits until it did, then identifies anew.
    auto* c = endat->add_subcommand(
        "rescan", "Make the module read the encoder's identification again (EnDatAck bit 1)");
    auto pos = std::make_shared<std::string>();
    c->add_option("AXIS", *pos, "Axis index (0-based; default --axis)");
    c->callback([&ctx, axis, pos] {
      Number n;
      n.text = pos->empty() ? axis->text : *pos;
      json request{{"cmd", "endat-rescan"}, {"axis", parse("AXIS", n, 0, 0xFFFF)}};
      ctx.action = [&ctx, request = std::move(request)] {
        return request_and_print(ctx, request, [](const json& r) {
          std::cout << "axis " << num(r, "axis") << ": rescan "
                    << (r.value("confirmed", false) ? "done" : "written (completion not readable)")
                    << " after " << r.value("wait_ms", 0.0) << " ms\n";
        });
      };
    });
  }

  {
    auto* c = endat->add_subcommand("read-param", "Read a parameter word (0x04)");
    auto mrs = std::make_shared<Number>(), param = std::make_shared<Number>();
    add_number(c, "MRS", *mrs, "Memory area (e.g. 0xA9)");
    add_number(c, "PARAM", *param, "Parameter number");
    c->callback([action, mrs, param] {
      action({{"cmd", "endat-read-param"},
              {"mrs", parse("MRS", *mrs, 0, 0xFF)},
              {"param", parse("PARAM", *param, 0, 0xFF)}},
             print_param);
    });
  }
  {
    auto* c = endat->add_subcommand("write-param",
                                    "Write a parameter word (0x05), verified by reading back");
    auto mrs = std::make_shared<Number>(), param = std::make_shared<Number>(),
         value = std::make_shared<Number>();
    add_number(c, "MRS", *mrs, "Memory area (e.g. 0xA9)");
    add_number(c, "PARAM", *param, "Parameter number");
    add_number(c, "VALUE", *value, "16-bit value");
    c->callback([action, mrs, param, value] {
      action({{"cmd", "endat-write-param"},
              {"mrs", parse("MRS", *mrs, 0, 0xFF)},
              {"param", parse("PARAM", *param, 0, 0xFF)},
              {"value", parse("VALUE", *value, 0, 0xFFFF)}},
             print_param);
    });
  }
  {
    auto* c =
        endat->add_subcommand("read-block", "Read a parameter of a memory block (0x06, EnDat 2.2)");
    auto mrs = std::make_shared<Number>(), block = std::make_shared<Number>(),
         param = std::make_shared<Number>();
    add_number(c, "MRS", *mrs, "Memory area (e.g. 0xB1)");
    add_number(c, "BLOCK", *block, "Block number");
    add_number(c, "PARAM", *param, "Parameter number");
    c->callback([action, mrs, block, param] {
      action({{"cmd", "endat-read-block"},
              {"mrs", parse("MRS", *mrs, 0, 0xFF)},
              {"block", parse("BLOCK", *block, 0, 0xFF)},
              {"param", parse("PARAM", *param, 0, 0xFF)}},
             print_param);
    });
  }
  {
    auto* c = endat->add_subcommand(
        "write-block", "Write a parameter of a memory block (0x07, EnDat 2.2), verified");
    auto mrs = std::make_shared<Number>(), block = std::make_shared<Number>(),
         param = std::make_shared<Number>(), value = std::make_shared<Number>();
    add_number(c, "MRS", *mrs, "Memory area (e.g. 0xB1)");
    add_number(c, "BLOCK", *block, "Block number");
    add_number(c, "PARAM", *param, "Parameter number");
    add_number(c, "VALUE", *value, "16-bit value");
    c->callback([action, mrs, block, param, value] {
      action({{"cmd", "endat-write-block"},
              {"mrs", parse("MRS", *mrs, 0, 0xFF)},
              {"block", parse("BLOCK", *block, 0, 0xFF)},
              {"param", parse("PARAM", *param, 0, 0xFF)},
              {"value", parse("VALUE", *value, 0, 0xFFFF)}},
             print_param);
    });
  }
  {
    auto* c = endat->add_subcommand(
        "read-info", "Read additional-information word 1..4 (0x08..0x0B, EnDat 2.2)");
    auto word = std::make_shared<Number>(), mrs = std::make_shared<Number>();
    add_number(c, "WORD", *word, "Word 1..4");
    add_number(c, "MRS", *mrs, "Additional information code (e.g. 0x4C temperature 1)");
    c->callback([action, word, mrs] {
      action({{"cmd", "endat-read-info"},
              {"word", parse("WORD", *word, 1, 4)},
              {"mrs", parse("MRS", *mrs, 0, 0xFF)}},
             print_info);
    });
  }
  {
    auto* c = endat->add_subcommand("ident", "The encoder's identification (read at daemon start)");
    auto refresh = std::make_shared<bool>(false);
    c->add_flag("--refresh", *refresh,
                "Rescan (EnDatAck bit 1), then read it from the encoder again");
    c->callback([action, refresh] {
      json request{{"cmd", "endat-ident"}};
      if (*refresh) request["refresh"] = true;
      action(std::move(request), print_ident);
    });
  }
  {
    auto* c =
        endat->add_subcommand("dump", "Read a whole memory area (16 words; 0xB9: 4, 0xBD: 64)");
    auto mrs = std::make_shared<Number>();
    add_number(c, "MRS", *mrs, "Memory area (e.g. 0xA1)");
    c->callback([action, mrs] {
      action({{"cmd", "endat-dump"}, {"mrs", parse("MRS", *mrs, 0, 0xFF)}}, print_dump);
    });
  }
}

}  // namespace ds1928::ctl
