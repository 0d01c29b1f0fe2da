// The PC side of one slave bus as a whole (docs/slave_bus_node.md): the master's link kept open,
// the inputs (explicit step frames, per-slave commands) checked against the slave table and the
// motion switch and queued, every step sent in turn on the link's thread, and what comes back
// decoded and counted. ROS-free: slave_bus_node reads its parameters into BusSettings and maps the
// listener's events to topics, state and diagnostics.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "cnc_bridge/common/safety_switch.h"
#include "cnc_bridge/slave_bus/bus_monitor.h"
#include "cnc_bridge/slave_bus/bus_session.h"
#include "cnc_bridge/slave_bus/slave_table.h"
#include "cnc_bridge/slave_bus/step_queue.h"
#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/transport/reconnecting_link.h"

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief Every setting of one bus (slave_bus_node's parameters).
struct BusSettings
{
  explicit BusSettings(SlaveTable slaves) : table(std::move(slaves)) {}

  SlaveTable table;                 ///< the slaves, the bus size and the master's WirePacker dialect
  LinkSettings link;                ///< the master's serial line
  Framing framing = Framing::kRaw;  ///< raw (the universal-CNC paper's bytes, docs/protocols/slave_bus.md#source) or
                                    ///< framed (WirePacker, CRC-8)
  size_t max_queued_steps = 100;    ///< steps waiting for the link; more are refused
  Milliseconds command_delay{5};    ///< a step of commands leaves this long after its first command
  Milliseconds reply_timeout{500};  ///< a slave that got a payload answers within this, or times out
  Milliseconds resync_gap{50};      ///< a partial uplink record followed by this silence is dropped
  Backoff backoff;                  ///< between attempts to reopen the link
};

/// \brief A slave's reply as the runner read it.
struct SlaveReply
{
  size_t index = 0;            ///< into BusSettings::table.slaves()
  std::vector<uint8_t> data;   ///< the payload as received
  std::vector<double> values;  ///< decoded in the slave's encoding (an axis: m); empty if not decodable
  bool decoded = false;
  bool axis_update = false;     ///< an axis slave's position: values[0]
  bool all_axes_known = false;  ///< with axis_update: every configured axis has reported a position
};

/// \brief Events of the runner, called on the link's thread (onRefused also on the caller's of
/// submitFrame/submitCommand), one at a time per thread.
class BusListener
{
 public:
  virtual ~BusListener() = default;
  /// The link's state changed; \p why is the failure text (empty when there is none).
  virtual void onLink(LinkState state, const std::string& why) {}
  /// A step is going out (\p active) or the last queued step has been sent (!\p active).
  virtual void onExecution(bool active) {}
  virtual void onReply(const SlaveReply& reply) {}
  /// A master status record (address 0), as the line to log (counted in the report).
  virtual void onMasterStatus(const std::string& what) {}
  /// An input refused or a step lost, with why (counted in the report).
  virtual void onRefused(const std::string& why) {}
  /// \p steps waiting for the link were dropped when it went down (counted in the report).
  virtual void onStepsDropped(size_t steps) {}
};

/// \brief One bus: its link, its step queue, its session loop and its counters. Thread-safe.
class BusRunner
{
 public:
  /// \param motion gates every payload that moves or cuts (axis, tool, unconfigured addresses);
  ///        must outlive the runner.
  /// \param listener must outlive the runner.
  /// \throws ConfigError for invalid link settings.
  BusRunner(BusSettings settings, const SafetySwitch& motion, BusListener& listener);
  /// Stops (stop()).
  ~BusRunner();
  BusRunner(const BusRunner&) = delete;
  BusRunner& operator=(const BusRunner&) = delete;

  /// \brief Opens the link (in its own thread, reopened after failures) and sends steps while it is
  /// up. Inputs are refused until it is.
  void start();
  /// \brief Ends the session and joins the link's thread; no event follows. Idempotent.
  void stop();

  /// \brief Queues an explicit step frame, (address, payload) pairs.
  /// \returns true if queued; false if refused (the listener was told why: a wrong frame, motion
  /// disabled for an address that moves, the link down, the queue full).
  bool submitFrame(const std::vector<std::pair<uint8_t, std::vector<uint8_t>>>& payloads);
  /// \brief Queues a command for slave \p index: raw \p data or \p values (SlaveTable::commandPayload).
  /// \returns true if queued; false if refused (the listener was told why).
  bool submitCommand(size_t index, const std::vector<double>& values, const std::vector<uint8_t>& data);

  const SlaveTable& table() const { return settings_.table; }
  const BusSettings& settings() const { return settings_; }
  /// \brief The counters now (BusMonitor::report()).
  BusMonitor::Report report() { return monitor_.report(); }

 private:
  bool refuse(const std::string& why);
  bool refuseNotQueued(const std::string& input);
  void onLinkState(LinkState state, const std::string& why);
  void run(Transport& port);
  void sendStep(BusSession& session, const StepPayloads& step);
  void handle(const std::vector<UplinkRecord>& records);
  void reply(size_t index, const UplinkRecord& record);

  const BusSettings settings_;
  const SafetySwitch& motion_;
  BusListener& listener_;
  StepQueue queue_;
  BusMonitor monitor_;
  std::set<Role> axis_seen_;  // link thread only
  ReconnectingLink link_;
};
}  // namespace slave_bus
}  // namespace cnc_bridge
