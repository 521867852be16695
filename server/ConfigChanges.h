#pragma once
// What a reload (SIGHUP) of the config file can change in a running daemon: its catalog
// ([[volume]], [[preset]]). Every other setting is read once, at start; a reload that finds one
// changed names it in the log, so an operator who edited listen or a timeout knows it waits for
// a restart.
#include "server/DaemonConfig.h"

#include <string>
#include <vector>

namespace bc::server {

/// The keys whose values differ between the running config and `next` (a reload's), but for
/// the catalog's: "server.listen", "timeouts.write_ms", ... A setting the command line
/// overrode (listen, metrics, web) is the command line's and is not named.
std::vector<std::string> settingsAReloadKeeps(const DaemonConfig& running,
                                              const DaemonConfig& next);

} // namespace bc::server
