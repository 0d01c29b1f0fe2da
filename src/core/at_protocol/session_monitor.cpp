// Diagnostics of the session with one '@' controller (session_monitor.h).
#include "cnc_bridge/at_protocol/session_monitor.h"

#include <chrono>
#include <sstream>

namespace cnc_bridge
{
namespace at_protocol
{
namespace
{
template <class T>
std::string text(const T& value)
{
  std::ostringstream out;
  out << value;
  return out.str();
}

std::string text(bool value)
{
  return value ? "True" : "False";
}
}  // namespace

SessionMonitor::Report SessionMonitor::report()
{
  const SetpointSender::Stats stats = session_.sender().stats();
  const Sequencer sequencer = session_.sender().sequencer();
  const ControllerSnapshot now = session_.snapshot();
  Report report;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (now.estop == EStop::kOn)
    {
      report = {Level::kError, "emergency stop (E1)", {}, {}};
    }
    else if (now.estop != EStop::kOff)
    {
      report = {Level::kWarn, "emergency stop state unknown (no E0/E1 report yet)", {}, {}};
    }
    else if (stats.underruns > underruns_seen_)
    {
      report = {Level::kWarn, "setpoint underruns since the last update", {}, {}};
    }
    else
    {
      report = {Level::kOk, std::string("phase: ") + toString(sequencer.phase()), {}, {}};
    }
    underruns_seen_ = stats.underruns;
  }
  report.streaming = {
      {"setpoints sent", text(stats.setpoints)},
      {"underruns (setpoint later than one period)", text(stats.underruns)},
      {"stalls (schedule fell more than one period behind)", text(stats.stalls)},
      {"latency mean (ms)", text(stats.mean_lateness * 1e3)},
      {"latency max (ms)", text(stats.max_lateness * 1e3)},
      {"interval p50 (ms)", text(stats.interval_p50 * 1e3)},
      {"interval p99 (ms)", text(stats.interval_p99 * 1e3)},
      {"interval max (ms)", text(stats.interval_max * 1e3)},
      {"commands sent", text(stats.commands)},
      {"command link reconnects", text(session_.commandReconnects())},
      {"report link reconnects", text(session_.reportReconnects())},
      {"report errors", text(session_.reportErrors())},
  };
  const std::string last_jog_stop = session_.lastJogStop();
  report.controller = {
      {"mode", now.jog_axis >= 0 ? std::string("jog ") + "XYZ"[now.jog_axis] : std::string("auto or unknown")},
      {"at home", text(now.at_home)},
      {"jog deadman (s, 0: off)", text(std::chrono::duration<double>(session_.jogDeadman().timeout()).count())},
      {"last jog stop", last_jog_stop.empty() ? std::string("none") : last_jog_stop},
      {"spindle value (0..255)", text(sequencer.spindle())},
  };
  return report;
}
}  // namespace at_protocol
}  // namespace cnc_bridge
