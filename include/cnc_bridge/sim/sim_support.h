// What every simulator shares: a clean stop on SIGINT/SIGTERM that also wakes blocking I/O, and
// the first line of output that tells the test or the user where the simulator listens.
#pragma once

#include <functional>
#include <string>

#include "cnc_bridge/transport/backoff.h"

namespace cnc_bridge
{
namespace sim
{
/// \brief Blocks SIGINT and SIGTERM and handles them in a thread: on the first one the returned
/// signal is stopped and every registered callback runs (to interrupt() transports). Call once,
/// at the start of main(), before other threads exist.
StopSignal& installStopHandler();

/// \brief Registers a callback to run on SIGINT/SIGTERM (e.g. [&]{ pty.interrupt(); }).
void onStop(std::function<void()> callback);

/// \brief Prints the first line of a simulator: "<what> <where>", flushed at once, e.g.
/// "sim_haas_serial pty /dev/pts/3" or "sim_ethernut tcp 127.0.0.1:6666".
void announce(const std::string& what, const std::string& where);
}  // namespace sim
}  // namespace cnc_bridge
