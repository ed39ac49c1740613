// Subcommand groups of ds1928ctl. Each group adds its subcommands to the app; a subcommand's
// callback sets ctx.action, which main() runs after parsing. A new group (e.g. `endat ...`) is
// one more function of this shape, registered in main.cpp.
#pragma once

#include <CLI/CLI.hpp>

#include "context.hpp"

namespace ds1928::ctl {

// status, axes, stats, ack, stats-reset: requests over the control socket.
void add_basic_commands(CLI::App& app, Context& ctx);
// position [--axis N] [--follow [--every N]]: read from shared memory.
void add_position_command(CLI::App& app, Context& ctx);
// endat reset|ack|read-param|write-param|read-block|write-block|read-info|ident|dump.
void add_endat_commands(CLI::App& app, Context& ctx);
// `pl pres` / `pl preq-set`: raw process data of POWERLINK CNs.
void add_powerlink_commands(CLI::App& app, Context& ctx);
// `capture -w FILE [--duration S | --count N] [--format F]`, `capture-stop` (privileged).
void add_capture_commands(CLI::App& app, Context& ctx);
// `incidents`, `incident mark TEXT` (the flight recorder).
void add_incident_commands(CLI::App& app, Context& ctx);
// `topology`: found vs expected (nodes, encoders).
void add_topology_command(CLI::App& app, Context& ctx);
// `doctor`: the machine's real-time settings against the configuration (no daemon needed).
void add_doctor_command(CLI::App& app, Context& ctx);

}  // namespace ds1928::ctl
