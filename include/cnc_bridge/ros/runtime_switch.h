// RuntimeSwitch: the ROS side of a SafetySwitch (cnc_bridge/common/safety_switch.h), the one
// design of a safety gate (motion, kill; docs/SAFETY.md): it starts from a private parameter and
// can be switched while the node runs through a std_srvs/SetBool service. The parameter is read
// once at start-up (`rosparam set` has no effect afterwards), so every refusal names both the
// service and the parameter; every switch is logged with the caller's node name (the service
// connection header's callerid) and shown in diagnostics. What a change does is a listener of the
// core switch (core() hands it to a core session), called under its gate.
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>

#include <functional>
#include <memory>
#include <string>

#include "cnc_bridge/common/safety_switch.h"
#include "cnc_bridge/ros/request_boundary.h"

namespace cnc_bridge
{
/// \brief One on/off gate: ~<parameter> at start-up, ~<service> (std_srvs/SetBool) at run time.
/// Thread-safe.
class RuntimeSwitch
{
 public:
  /// Called after each change (on the service's thread, under the switch's gate) with the new
  /// value and the caller.
  using OnChange = std::function<void(bool enabled, const std::string& caller)>;

  /// \param what the gated thing in words ("motion", "kill").
  /// \param parameter private parameter with the start-up value (default false: off unless configured on).
  /// \param service private service that switches it.
  RuntimeSwitch(ros::NodeHandle pnh, const std::string& what, const std::string& parameter, const std::string& service,
                OnChange on_change = nullptr)
      : core_(std::make_shared<SafetySwitch>(
            SafetySwitch::Names{what, pnh.resolveName(service), pnh.resolveName(parameter)},
            pnh.param(parameter, false)))
  {
    if (on_change)
    {
      core_->subscribe(std::move(on_change));
    }
    service_ = advertiseGuardedService(pnh, service, &RuntimeSwitch::onSet, this);
  }

  /// \brief Sets the value as a change by \p caller would (e.g. a value read from a settings file).
  void set(bool enabled, const std::string& caller) { core_->set(enabled, caller); }

  bool enabled() const { return core_->enabled(); }

  /// \brief The core switch, for a core session that gates its motion on it.
  SafetySwitch& core() { return *core_; }
  std::shared_ptr<SafetySwitch> shared() { return core_; }

  /// \brief "<action> refused: motion is disabled; enable it with <service> (std_srvs/SetBool), or
  /// start the node with <parameter> true".
  std::string refusal(const std::string& action) const { return core_->refusal(action); }

  /// \brief Adds "<what> enabled" and "<what> last change" to a diagnostics status.
  void addTo(diagnostic_updater::DiagnosticStatusWrapper& status) const
  {
    const std::string what = core_->names().what;
    status.add(what + " enabled", core_->enabled());
    status.add(what + " last change", core_->lastChange());
  }

 private:
  bool onSet(ros::ServiceEvent<std_srvs::SetBool::Request, std_srvs::SetBool::Response>& event)
  {
    const bool enable = event.getRequest().data;
    // The connection header's callerid: the node that called, for the log and diagnostics.
    const std::string caller = event.getCallerName().empty() ? "an unnamed caller" : event.getCallerName();
    const std::string& what = core_->names().what;
    const bool was = core_->set(enable, caller, std::to_string(ros::WallTime::now().toSec()));
    ROS_WARN_STREAM(core_->names().service << ": " << what << (enable ? " enabled" : " disabled") << " by " << caller
                                           << (was == enable ? " (no change)" : ""));
    auto& response = event.getResponse();
    response.success = true;
    response.message = what + (enable ? " enabled" : " disabled") + " by " + caller;
    return true;
  }

  std::shared_ptr<SafetySwitch> core_;
  ros::ServiceServer service_;
};
}  // namespace cnc_bridge
