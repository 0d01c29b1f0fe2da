// SafetySwitch: one on/off gate of a node that moves or cuts (the motion switch, the kill switch;
// docs/SAFETY.md). Every node holds its gates this one way: the switch is the one place the value
// lives (nothing mirrors it), what a change must do (pause a board, decelerate a path, stop a jog,
// hold a job) is a listener of the switch, and an action that must not race a change (the start
// of a job's next segment, a command that moves) runs under the switch's gate. ROS-free: the ROS
// side (cnc_bridge/ros/runtime_switch.h) reads the start-up value from a parameter, switches it
// from a std_srvs/SetBool service and shows it in diagnostics.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>

namespace cnc_bridge
{
/// \brief One on/off gate, thread-safe.
///
/// A change and its listeners run under the gate, so a gated action sees the value and every
/// effect of a change, or none of it:
/// \code
///   auto gate = motion.gate();
///   if (!motion.enabled()) return motion.refusal("job");
///   board.startSegment();  // a disable comes wholly before (refused) or after (its listener pauses)
/// \endcode
class SafetySwitch
{
 public:
  /// Names used in texts; empty names are left out of them.
  struct Names
  {
    std::string what = "motion";  ///< the gated thing in words ("motion", "kill")
    std::string service;          ///< what switches it at run time ("/cell/mill/set_motion_enabled")
    std::string parameter;        ///< what gives its start-up value ("/cell/mill/enable_motion")
  };
  /// Called after each change (set()) with the new value and who changed it, under the gate: it
  /// may call enabled(), refusal(), gate() (the gate is recursive), not set().
  using Listener = std::function<void(bool enabled, const std::string& by)>;
  using Subscription = uint64_t;

  SafetySwitch(Names names, bool initial);
  SafetySwitch(const SafetySwitch&) = delete;
  SafetySwitch& operator=(const SafetySwitch&) = delete;

  bool enabled() const { return enabled_.load(); }

  /// \brief Switches it (\p by: who, e.g. a node name or "PROG_CNCkill|1 in /etc/board.tss";
  /// \p at: when, "" to leave out) and calls the listeners, in the order they subscribed.
  /// \returns the value before.
  bool set(bool enabled, const std::string& by, const std::string& at = "");

  /// \returns who disabled it last ("" if nobody has since the start).
  std::string disabledBy() const;
  /// \returns "start-up value of <parameter>", or "enabled by <who> [at <when>]".
  std::string lastChange() const;

  /// \brief "<action> refused: motion is disabled; enable it with <service> (std_srvs/SetBool, data:
  /// true), or start the node with the parameter <parameter> true" (without the names it lacks).
  std::string refusal(const std::string& action) const;

  /// \brief Calls \p listener after each change from now on, until unsubscribe().
  Subscription subscribe(Listener listener);
  /// \brief Stops calling a listener; waits for a call in progress on another thread to end.
  void unsubscribe(Subscription subscription);

  /// \brief Holds changes off while the lock lives: check enabled() and start what moves under it.
  std::unique_lock<std::recursive_mutex> gate() const { return std::unique_lock<std::recursive_mutex>(gate_); }

  const Names& names() const { return names_; }

 private:
  const Names names_;
  mutable std::recursive_mutex gate_;  ///< a change and its listeners; the gated actions
  std::atomic<bool> enabled_;
  mutable std::mutex text_mutex_;  ///< last_change_, disabled_by_
  std::string last_change_;
  std::string disabled_by_;
  std::map<Subscription, Listener> listeners_;  ///< under gate_
  Subscription next_subscription_ = 1;
};
}  // namespace cnc_bridge
