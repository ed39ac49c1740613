// ds1928ctl: talk to ds1928d. Readable output by default, --json for scripts.
#include <CLI/CLI.hpp>
#include <iostream>

#include "commands.hpp"
#include "context.hpp"

int main(int argc, char** argv) {
  using namespace ds1928::ctl;
  Context ctx;
  CLI::App app{"ds1928ctl: control and observe the ds1928d encoder daemon", "ds1928ctl"};
  app.footer(
      "Exit codes: 0 ok, 1 the daemon answered with an error, 2 usage, 3 cannot reach the daemon\n"
      "(socket or shared memory) or it is gone, 4 invalid reply from the daemon.");
  app.require_subcommand(1);
  app.fallthrough();  // global options are accepted after the subcommand too
  app.add_option("--socket,-s", ctx.socket_path, "Control socket of the daemon")
      ->capture_default_str();
  app.add_option("--shm", ctx.shm_name, "Shared memory name of the daemon")->capture_default_str();
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

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);  // prints help or the error
    return e.get_exit_code() == 0 ? rc : kUsage;
  }
  return ctx.action ? ctx.action() : kUsage;
}
