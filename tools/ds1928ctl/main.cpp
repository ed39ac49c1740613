// ds1928ctl: talk to ds1928d. Readable output by default, --json for scripts.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"
#include "context.hpp"

namespace {

// Edit distance with adjacent transpositions ("stauts" is one step from "status").
std::size_t distance(const std::string& a, const std::string& b) {
  std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
  for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  }
  return d[a.size()][b.size()];
}

const CLI::Option* find_option(const CLI::App* app, const std::string& name) {
  for (; app != nullptr; app = app->get_parent()) {
    if (const CLI::Option* o = app->get_option_no_throw(name)) return o;
  }
  return nullptr;
}

// A command word the tool does not know, found before CLI11 parses (it would only say "A
// subcommand is required"): "unknown command 'stauts'; did you mean 'status'?" and the exit
// code of a usage error, or nullopt when every command word is known.
std::optional<std::string> unknown_command(const CLI::App& app, int argc, char** argv) {
  const CLI::App* current = &app;
  for (int i = 1; i < argc; ++i) {
    const std::string token = argv[i];
    if (token == "--") return std::nullopt;
    if (token.size() > 1 && token[0] == '-') {
      const std::string name = token.substr(0, token.find('='));
      const CLI::Option* o = find_option(current, name);
      if (o != nullptr && o->get_expected_min() > 0 && name == token) ++i;  // its value
      continue;
    }
    const auto subs = current->get_subcommands([](const CLI::App*) { return true; });
    if (subs.empty()) return std::nullopt;  // the rest are positional arguments
    const CLI::App* next = nullptr;
    for (const CLI::App* s : subs)
      if (s->check_name(token)) next = s;
    if (next != nullptr) {
      current = next;
      continue;
    }
    std::string best;
    std::size_t best_distance = 3;  // suggest only what is at most 2 edits away
    std::string all;
    for (const CLI::App* s : subs) {
      all += (all.empty() ? "" : ", ") + s->get_name();
      const std::size_t dist = distance(token, s->get_name());
      if (dist < best_distance) {
        best_distance = dist;
        best = s->get_name();
      }
    }
    const std::string where = current == &app ? std::string() : " of '" + current->get_name() + "'";
    return "unknown command '" + token + "'" + where +
           (best.empty() ? "; commands: " + all : "; did you mean '" + best + "'?");
  }
  return std::nullopt;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace ds1928::ctl;
  Context ctx;
  CLI::App app{"ds1928ctl: control and observe the ds1928d encoder daemon", "ds1928ctl"};
  app.set_version_flag("--version", "ds1928ctl " PROJECT_VERSION);
  app.footer(
      "Exit codes: 0 ok, 1 the daemon answered with an error, 2 usage, 3 cannot reach the daemon\n"
      "(socket or shared memory) or it is gone, 4 invalid reply from the daemon, 5 (--check) an\n"
      "axis is not valid.\n"
      "The socket: -s, else $DS1928_SOCKET, else /run/ds1928d/control.sock; each followed by the\n"
      "fallback a daemon without root uses ($XDG_RUNTIME_DIR/ds1928d/ or /tmp/ds1928d-UID/).");
  app.require_subcommand(1);
  app.fallthrough();  // global options are accepted after the subcommand too
  app.add_option("--socket,-s", ctx.socket_path,
                 "Control socket of the daemon (default: $DS1928_SOCKET, else /run/ds1928d/"
                 "control.sock, then the per-user fallback)");
  app.add_option("--shm", ctx.shm_name,
                 "Shared memory name (default: the one the daemon reports, else /ds1928d)");
  app.add_flag("--json,-j", ctx.json, "Machine-readable output: one JSON object per line");
  app.add_option("--timeout", ctx.timeout_ms, "Reply timeout in ms")
      ->check(CLI::Range(1, 3'600'000))
      ->capture_default_str();

  add_basic_commands(app, ctx);
  add_position_command(app, ctx);
  add_endat_commands(app, ctx);
  add_powerlink_commands(app, ctx);
  add_capture_commands(app, ctx);
  add_incident_commands(app, ctx);
  add_topology_command(app, ctx);
  add_doctor_command(app, ctx);

  if (const auto unknown = unknown_command(app, argc, argv)) {
    std::cerr << "ds1928ctl: " << *unknown << "\nRun with --help for more information.\n";
    return kUsage;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);  // prints help or the error
    return e.get_exit_code() == 0 ? rc : kUsage;
  }
  resolve_sockets(ctx, std::getenv("DS1928_SOCKET"));
  return ctx.action ? ctx.action() : kUsage;
}
