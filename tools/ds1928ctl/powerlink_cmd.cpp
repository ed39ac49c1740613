// `ds1928ctl pl pres NODE` / `ds1928ctl pl preq-set NODE OFFSET HEX`: raw process data of a
// POWERLINK Controlled Node (pl-pres / pl-preq-set in docs/socket-protocol.md).
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "client.hpp"
#include "commands.hpp"
#include "endat/number.hpp"

namespace ds1928::ctl {

void add_powerlink_commands(CLI::App& app, Context& ctx) {
  auto* pl = app.add_subcommand("pl", "POWERLINK raw process data of a Controlled Node");
  pl->require_subcommand(1);

  auto* pres = pl->add_subcommand("pres", "The CN's last PRes payload");
  auto node = std::make_shared<std::string>();
  pres->add_option("NODE", *node, "CN node id, 1..239")->required();
  pres->callback([&ctx, node] {
    const auto n = endat::parse_number(*node, 1, 239);
    if (!n) throw CLI::ValidationError("NODE", "'" + *node + "': " + n.error().message());
    ctx.action = [&ctx, n = *n] {
      return request_and_print(ctx, {{"cmd", "pl-pres"}, {"node", n}}, [](const nlohmann::json& r) {
        std::cout << "node " << r.value("node", 0) << ": " << r.value("size", 0) << " bytes"
                  << (r.value("fresh", false) ? " (fresh" : " (not fresh")
                  << (r.value("ready", true) ? ")" : ", RD = 0: data not ready)") << "\n  "
                  << r.value("hex", std::string()) << "\n";
      });
    };
  });

  auto* preq = pl->add_subcommand("preq-set", "Set bytes of the CN's PReq payload");
  auto pnode = std::make_shared<std::string>();
  auto offset = std::make_shared<std::string>();
  auto hex = std::make_shared<std::string>();
  preq->add_option("NODE", *pnode, "CN node id, 1..239")->required();
  preq->add_option("OFFSET", *offset, "byte offset in the PReq payload")->required();
  preq->add_option("HEX", *hex, "bytes as hex digits, e.g. 0a1b2c")->required();
  preq->callback([&ctx, pnode, offset, hex] {
    const auto n = endat::parse_number(*pnode, 1, 239);
    if (!n) throw CLI::ValidationError("NODE", "'" + *pnode + "': " + n.error().message());
    const auto o = endat::parse_number(*offset, 0, 1489);
    if (!o) throw CLI::ValidationError("OFFSET", "'" + *offset + "': " + o.error().message());
    ctx.action = [&ctx, n = *n, o = *o, hex] {
      return request_and_print(
          ctx, {{"cmd", "pl-preq-set"}, {"node", n}, {"offset", o}, {"hex", *hex}},
          [](const nlohmann::json& r) {
            std::cout << "node " << r.value("node", 0) << ": " << r.value("size", 0)
                      << " bytes set at offset " << r.value("offset", 0) << " (PReq "
                      << r.value("preq_size", 0) << " bytes)\n";
          });
    };
  });
}

}  // namespace ds1928::ctl
