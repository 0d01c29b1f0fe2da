// A clean stop on SIGINT/SIGTERM for command-line programs (cnc_dnc, the simulators): the signal
// is taken in a thread of its own, which stops a StopSignal and runs callbacks that wake blocking
// I/O (a transport's interrupt()).
#pragma once

#include <functional>

#include "cnc_bridge/transport/backoff.h"

namespace cnc_bridge
{
/// \brief Blocks SIGINT and SIGTERM and handles them in a thread: on the first one the returned
/// signal is stopped and every registered callback runs (to interrupt() transports). Call once,
/// at the start of main(), before other threads exist.
StopSignal& installStopHandler();

/// \brief Registers a callback to run on SIGINT/SIGTERM (e.g. [&]{ pty.interrupt(); }).
void onStop(std::function<void()> callback);
}  // namespace cnc_bridge
