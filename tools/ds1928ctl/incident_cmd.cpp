// `incidents` (the flight recorder's files) and `incident mark TEXT`.
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "client.hpp"
#include "commands.hpp"

namespace ds1928::ctl {
namespace {

using json = nlohmann::json;

std::string or_dash(const json& v) {
  if (v.is_null()) return "-";
  if (v.is_string()) return v.get<std::string>();
  return v.dump();
}

void print_incidents(const json& r) {
  const json& list = r.at("incidents");
  if (list.empty())
    std::cout << "no incident since the daemon started\n";
  else
    std::printf("%-4s %-27s %-16s %-5s %-5s %8s  %s\n", "#", "time (UTC)", "kind", "node", "axis",
                "frames", "file");
  for (const json& i : list) {
    const std::string file = i.value("file", json()).is_null()
                                 ? "(no file: " + or_dash(i.value("error", json())) + ")"
                                 : i.at("file").get<std::string>();
    std::printf("%-4llu %-27s %-16s %-5s %-5s %8llu  %s\n",
                static_cast<unsigned long long>(i.value("number", uint64_t{0})),
                i.value("time", std::string("?")).c_str(), i.value("kind", std::string()).c_str(),
                or_dash(i.value("node", json())).c_str(), or_dash(i.value("axis", json())).c_str(),
                static_cast<unsigned long long>(i.value("frames", uint64_t{0})), file.c_str());
    std::printf("     %s%s\n", i.value("text", std::string()).c_str(),
                i.value("count", 1) > 1
                    ? (" (" + std::to_string(i.value("count", 1)) + " times)").c_str()
                    : "");
  }
  const json& earlier = r.value("earlier_files", json::array());
  if (!earlier.empty()) {
    std::cout << earlier.size() << " file(s) of earlier runs:\n";
    for (const json& f : earlier)
      std::cout << "  " << f.value("file", std::string()) << " (" << f.value("bytes", uint64_t{0})
                << " bytes)\n";
  }
  if (r.value("pending", 0) > 0)
    std::cout << r.value("pending", 0) << " incident(s) waiting for their tail\n";
}

}  // namespace

void add_incident_commands(CLI::App& app, Context& ctx) {
  app.add_subcommand("incidents",
                     "Incidents the flight recorder wrote: time, kind, node, frames, file")
      ->callback([&ctx] {
        ctx.action = [&ctx] {
          return request_and_print(ctx, {{"cmd", "incidents"}}, print_incidents);
        };
      });
  auto* incident = app.add_subcommand("incident", "Mark an incident by hand");
  incident->require_subcommand(1);
  auto text = std::make_shared<std::string>();
  auto* mark = incident->add_subcommand(
      "mark", "Write the flight recorder's window around now to an incident file (privileged)");
  mark->add_option("TEXT", *text, "What happened (in the journal and the listing)");
  mark->callback([&ctx, text] {
    ctx.action = [&ctx, text] {
      return request_and_print(ctx, {{"cmd", "incident-mark"}, {"text", *text}}, [](const json& r) {
        const json& m = r.at("marked");
        if (m.value("joined", false)) {
          std::cout << "joined the manual incident still pending\n";
        } else if (m.contains("note") && m["note"].is_string()) {
          // The daemon's own words: where the file goes, or why none is written.
          std::cout << "incident " << or_dash(m.value("number", json())) << " marked; "
                    << m["note"].get<std::string>() << "\n";
        } else {
          std::cout << "incident " << or_dash(m.value("number", json()))
                    << " marked; its file follows in " << m.value("file_after_ms", 0) << " ms in "
                    << or_dash(m.value("dir", json())) << "\n";
        }
      });
    };
  });
}

}  // namespace ds1928::ctl
