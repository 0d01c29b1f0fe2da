// One MDC session of a node: what the node's parameters say (MdcSettings, read in the ROS layer by
// haas_mdc_params.cpp) -> the link through the link factory, the serial-port lock shared with a
// DNC transfer, the poller and the thread that reconnects and polls. ROS-free; the node maps what
// the poller reports to ROS.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "cnc_bridge/common/port_lock.h"
#include "cnc_bridge/mdc/mdc_monitor.h"
#include "cnc_bridge/mdc/mdc_readings.h"
#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/transport/reconnecting_link.h"

namespace cnc_bridge
{
namespace mdc
{
/// \brief Everything an MDC session is set up from (docs/haas_mdc_node.md, parameters).
struct MdcSettings
{
  LinkSettings link;                       ///< TCP to an NGC, or a Classic's serial port
  std::string lock_dir = kDefaultLockDir;  ///< serial: where the port lock shared with dnc_node lives
  Milliseconds reply_timeout{1000};        ///< one query's wait for its reply
  PollPlan plan;                           ///< what is polled how often (vars already added)
  PollVariables vars;                      ///< which variables are positions, spindle, extra, watched
  std::vector<int> writable_variables;     ///< what ~write_variable may set; empty: none
  bool forward_dprnt = false;              ///< serial: the port also carries DPRNT (see MdcClient)
};

/// \brief The link, the port lock and the poller of one control. Set the poller's listeners before
/// start(); stop() (or the destructor) ends the polling thread.
class MdcSession
{
 public:
  explicit MdcSession(const MdcSettings& settings);
  ~MdcSession();
  MdcSession(const MdcSession&) = delete;
  MdcSession& operator=(const MdcSession&) = delete;

  MdcPoller& poller() { return *poller_; }
  const MdcPoller& poller() const { return *poller_; }
  /// \brief What diagnostics call the device ("/dev/ttyUSB0@9600 7E1", "10.0.0.5:5051").
  std::string hardwareId() const { return hardware_id_; }

  /// \brief Opens the link and polls in a thread, reconnecting with backoff; \p on_state hears of
  /// each link change.
  void start(ReconnectingLink::StateHandler on_state);
  void stop();
  unsigned reconnects() const { return link_ ? link_->reconnects() : 0u; }

 private:
  std::string hardware_id_;
  LinkFactory open_;
  std::unique_ptr<PortLock> port_lock_;  // before poller_, which uses it
  std::unique_ptr<MdcPoller> poller_;
  StopSignal stop_;
  std::unique_ptr<ReconnectingLink> link_;
};
}  // namespace mdc
}  // namespace cnc_bridge
