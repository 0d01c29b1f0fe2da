// What the session with one '@' controller shows in diagnostics (docs/at_controller_node.md,
// topics, frames, diagnostics): the e-stop or setpoint underruns since the last report as the
// level, the sender's streaming counters and timing, the links' reconnects and report errors, and
// what the controller last reported, the jog deadman and the spindle. ROS-free: the node copies a
// report into its diagnostic status as it is.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/at_protocol/controller_session.h"

namespace cnc_bridge
{
namespace at_protocol
{
/// \brief Reports of one session for diagnostics. Thread-safe.
class SessionMonitor
{
 public:
  /// \param session must outlive the monitor.
  explicit SessionMonitor(ControllerSession& session) : session_(session) {}

  enum class Level
  {
    kOk,
    kWarn,
    kError
  };
  using Values = std::vector<std::pair<std::string, std::string>>;
  struct Report
  {
    Level level = Level::kOk;
    std::string summary;
    Values streaming;   ///< the sender's counters and timing, the links' reconnects, report errors
    Values controller;  ///< mode, home, the jog deadman and its last stop, the spindle value
  };
  /// \brief The session now; the level is WARN if setpoints underran since the last report (or
  /// ERROR on an e-stop, WARN while the e-stop is unknown). Values are written as
  /// diagnostic_updater writes numbers (a stream's default format) and booleans ("True", "False").
  Report report();

 private:
  ControllerSession& session_;
  std::mutex mutex_;  // guards underruns_seen_
  uint64_t underruns_seen_ = 0;
};
}  // namespace at_protocol
}  // namespace cnc_bridge
