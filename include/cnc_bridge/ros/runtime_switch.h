// RuntimeSwitch: a safety gate (motion, kill) that starts from a private parameter and can be
// switched while the node runs through a std_srvs/SetBool service (docs/SAFETY.md). The parameter
// is read once at start-up (`rosparam set` has no effect afterwards), so every refusal names both
// the service and the parameter; every switch is logged with the caller's node name (the service
// connection header's callerid) and shown in diagnostics.
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>

#include <atomic>
#include <functional>
#include <mutex>
#include <string>

#include "cnc_bridge/ros/request_boundary.h"

namespace cnc_bridge
{
/// \brief One on/off gate: ~<parameter> at start-up, ~<service> (std_srvs/SetBool) at run time.
/// Thread-safe.
class RuntimeSwitch
{
 public:
  /// Called after each change (on the service's thread) with the new value and the caller.
  using OnChange = std::function<void(bool enabled, const std::string& caller)>;

  /// \param what the gated thing in words ("motion", "kill").
  /// \param parameter private parameter with the start-up value (default false: off unless configured on).
  /// \param service private service that switches it.
  RuntimeSwitch(ros::NodeHandle pnh, const std::string& what, const std::string& parameter, const std::string& service,
                OnChange on_change = nullptr)
      : what_(what),
        parameter_(pnh.resolveName(parameter)),
        service_name_(pnh.resolveName(service)),
        on_change_(std::move(on_change))
  {
    bool initial = false;
    pnh.param(parameter, initial, false);
    enabled_ = initial;
    last_change_ = std::string("start-up value of ") + parameter_;
    service_ = advertiseGuardedService(pnh, service, &RuntimeSwitch::onSet, this);
  }

  /// \brief Sets the value as a change by \p caller would (e.g. a value read from a settings file).
  void set(bool enabled, const std::string& caller)
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      enabled_ = enabled;
      last_change_ = std::string(enabled ? "enabled" : "disabled") + " by " + caller;
    }
  }

  bool enabled() const { return enabled_.load(); }

  /// \brief "<action> refused: motion is disabled; enable it with <service> (std_srvs/SetBool), or
  /// start the node with <parameter> true".
  std::string refusal(const std::string& action) const
  {
    return action + " refused: " + what_ + " is disabled; enable it with " + service_name_ +
           " (std_srvs/SetBool, data: true), or start the node with the parameter " + parameter_ + " true";
  }

  /// \brief Adds "<what> enabled" and "<what> last change" to a diagnostics status.
  void addTo(diagnostic_updater::DiagnosticStatusWrapper& status) const
  {
    std::lock_guard<std::mutex> lock(mutex_);
    status.add(what_ + " enabled", enabled_.load());
    status.add(what_ + " last change", last_change_);
  }

 private:
  bool onSet(ros::ServiceEvent<std_srvs::SetBool::Request, std_srvs::SetBool::Response>& event)
  {
    const bool enable = event.getRequest().data;
    // The connection header's callerid: the node that called, for the log and diagnostics.
    const std::string caller = event.getCallerName().empty() ? "an unnamed caller" : event.getCallerName();
    bool was;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      was = enabled_.exchange(enable);
      last_change_ = std::string(enable ? "enabled" : "disabled") + " by " + caller + " at " +
                     std::to_string(ros::WallTime::now().toSec());
    }
    ROS_WARN_STREAM(service_name_ << ": " << what_ << (enable ? " enabled" : " disabled") << " by " << caller
                                  << (was == enable ? " (no change)" : ""));
    auto& response = event.getResponse();
    response.success = true;
    response.message = what_ + (enable ? " enabled" : " disabled") + " by " + caller;
    if (on_change_)
      on_change_(enable, caller);
    return true;
  }

  const std::string what_;
  const std::string parameter_;
  const std::string service_name_;
  OnChange on_change_;
  mutable std::mutex mutex_;  ///< last_change_, and enabled_ together with it
  std::atomic<bool> enabled_{false};
  std::string last_change_;
  ros::ServiceServer service_;
};
}  // namespace cnc_bridge
