// `topology`: what is on the bus next to what the configuration expects, differences marked.
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "client.hpp"
#include "commands.hpp"

namespace ds1928::ctl {
namespace {

using json = nlohmann::json;

std::string field(const json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || j[key].is_null()) return "-";
  return j[key].is_string() ? j[key].get<std::string>() : j[key].dump();
}

void print_topology(const json& r) {
  std::cout << "bus " << r.value("bus", std::string()) << ", on_mismatch "
            << r.value("on_mismatch", std::string()) << "  ('!' marks a difference)\n";
  std::printf("  %-3s %-12s %-4s %-4s %-6s  %-13s %-13s  %-13s %-13s  %s\n", "#", "axis", "node",
              "slot", "module", "expected ID", "found ID", "expected SN", "found SN", "state");
  for (const json& a : r.value("axes", json::array())) {
    const json& e = a.value("expected", json());
    const json& f = a.value("found", json());
    const bool diff = !a.value("difference", json()).is_null();
    std::printf("%s %-3llu %-12s %-4llu %-4llu %-6s  %-13s %-13s  %-13s %-13s  %s%s\n",
                diff ? "!" : " ", static_cast<unsigned long long>(a.value("axis", 0ULL)),
                a.value("name", std::string()).c_str(),
                static_cast<unsigned long long>(a.value("node", 0ULL)),
                static_cast<unsigned long long>(a.value("slot", 0ULL)),
                a.value("module_state", std::string("-")).c_str(), field(e, "id_number").c_str(),
                field(f, "id_number").c_str(), field(e, "serial_number").c_str(),
                field(f, "serial_number").c_str(), a.value("state", std::string()).c_str(),
                a.value("held_down", false) ? " (held bus_down)" : "");
    if (diff) std::cout << "      " << a["difference"].get<std::string>() << "\n";
    if (const std::string e = a.value("module_error_class", std::string("none")); e != "none")
      std::cout << "      module e-LED: " << e << "\n";
  }
  const json& nodes = r.value("nodes", json::array());
  if (nodes.empty()) return;
  // Per node (POWERLINK CN or CAN-I/O node): each identity object expected | found.
  std::printf("  %-4s  %-10s %-10s  %-10s %-10s  %-10s %-10s  %-10s %-10s  %s\n", "node",
              "exp vendor", "found", "exp prod.", "found", "exp rev.", "found", "exp serial",
              "found", "state");
  for (const json& n : nodes) {
    const json& e = n.value("expected", json());
    const json& f = n.value("found", json());
    const bool diff = !n.value("difference", json()).is_null();
    std::string state = n.value("state", std::string());
    const std::string boot = n.value("boot", std::string());
    if (state.empty())
      state = boot;
    else if (!boot.empty())
      state += ", " + boot;
    if (n.value("held_down", false)) state += " (held down)";
    std::printf("%s %-4llu  %-10s %-10s  %-10s %-10s  %-10s %-10s  %-10s %-10s  %s\n",
                diff ? "!" : " ", static_cast<unsigned long long>(n.value("node", 0ULL)),
                field(e, "vendor_id").c_str(), field(f, "vendor_id").c_str(),
                field(e, "product_code").c_str(), field(f, "product_code").c_str(),
                field(e, "revision_no").c_str(), field(f, "revision_no").c_str(),
                field(e, "serial_no").c_str(), field(f, "serial_no").c_str(), state.c_str());
    if (diff) std::cout << "      " << field(n, "difference") << "\n";
  }
}

}  // namespace

void add_topology_command(CLI::App& app, Context& ctx) {
  app.add_subcommand("topology",
                     "Nodes and encoders found on the bus next to the expected ones, "
                     "differences marked")
      ->callback([&ctx] {
        ctx.action = [&ctx] {
          return request_and_print(ctx, {{"cmd", "topology"}}, print_topology);
        };
      });
}

}  // namespace ds1928::ctl
