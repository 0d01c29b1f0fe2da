// What every simulator shares: a clean stop on SIGINT/SIGTERM that also wakes blocking I/O
// (cnc_bridge/common/stop_handler.h), and the first line of output that tells the test or the user
// where the simulator listens.
#pragma once

#include <string>

#include "cnc_bridge/common/stop_handler.h"

namespace cnc_bridge
{
namespace sim
{
using cnc_bridge::installStopHandler;
using cnc_bridge::onStop;

/// \brief Prints the first line of a simulator: "<what> <where>", flushed at once, e.g.
/// "sim_haas_serial pty /dev/pts/3" or "sim_ethernut tcp 127.0.0.1:6666".
void announce(const std::string& what, const std::string& where);

/// \brief Writes this process's id to \p path (a simulator's --pid-file), for a test that signals
/// or stops the simulator. \throws ConfigError if the file cannot be written.
void writePidFile(const std::string& path);
}  // namespace sim
}  // namespace cnc_bridge
