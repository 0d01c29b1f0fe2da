// What every cnc_bridge node publishes about its machine (docs/ROS_INTERFACE.md): the latched `state`
// topic, `joint_states` for robot_state_publisher, the tf frames machine -> tool and machine ->
// work, and diagnostics with the link status. Nodes change the state through update(); this class
// decides when to publish.
#pragma once

#include <diagnostic_updater/diagnostic_updater.h>
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <tf2_ros/transform_broadcaster.h>

#include <functional>
#include <mutex>
#include <string>

#include "cnc_bridge/CycleEvent.h"
#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/transport/reconnecting_link.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
/// \brief The transform \p parent -> \p child that is the translation \p p (m), no rotation.
geometry_msgs::TransformStamped translationTransform(const ros::Time& stamp, const std::string& parent,
                                                     const std::string& child, const geometry_msgs::Point& p);

/// \brief Publishes one machine's state, joints, tf and link diagnostics. Thread-safe.
///
/// Parameters (private): ~machine (string, default: the node name), ~tf_prefix (string, default ""),
/// ~state_rate (Hz, default 10; also the rate of joint_states and tf).
class MachineStatePublisher
{
 public:
  /// \param hardware_id what diagnostics call the device ("/dev/ttyUSB0@115200", "10.0.0.5:6666").
  MachineStatePublisher(ros::NodeHandle nh, ros::NodeHandle pnh, const std::string& hardware_id);

  /// \brief Changes the state under the lock; publishes at once if anything changed.
  /// The header stamp is set to now unless the mutator sets it.
  void update(const std::function<void(MachineState&)>& mutate);
  /// \brief Sets the link state and its message. An empty message keeps the current one while the
  /// link is down or connecting, and clears it when the link is up (the error no longer holds).
  void setLink(LinkState link, const std::string& message = "");
  /// \brief The state handler to start a ReconnectingLink with: its changes become this machine's
  /// link state (the state topic and the link diagnostics). Calls setLink(); a node that does more
  /// on a change (forget what it knew of the machine) calls it from its own handler.
  ReconnectingLink::StateHandler linkStateHandler()
  {
    return [this](LinkState link, const std::string& why) { setLink(link, why); };
  }
  /// \brief Sets the tool position in metres (machine frame) and marks it valid.
  void setPosition(double x, double y, double z);
  /// \brief Sets the last position sent to the machine in metres (machine frame) and marks it valid.
  /// Nodes that command no position never call it: commanded_valid stays false.
  void setCommandedPosition(double x, double y, double z);

  /// \brief A cycle event of this machine (its name, its machine frame): \p cycle_time in s, NaN in
  /// the message when negative (unknown); \p part_count -1 when unknown.
  CycleEvent cycleEvent(const ros::Time& stamp, uint8_t event, const std::string& program, int64_t part_count,
                        double cycle_time, const std::string& text) const;

  MachineState snapshot() const;
  const std::string& tfPrefix() const { return tf_prefix_; }
  const std::string& machineName() const { return machine_; }
  /// \brief ~state_rate (Hz): how often the state, joints and tf go out.
  double stateRate() const { return state_rate_; }
  /// \brief Frame names with the prefix: frame("tool") -> "<tf_prefix>tool".
  std::string frame(const std::string& name) const { return tf_prefix_ + name; }
  /// \brief The node's diagnostic updater, for protocol-specific tasks.
  diagnostic_updater::Updater& diagnostics() { return updater_; }

  static uint8_t toMessage(LinkState link);

 private:
  void publishLocked(const ros::Time& now);
  void onTimer(const ros::TimerEvent& event);
  void linkStatus(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_;
  std::string machine_;
  std::string tf_prefix_;
  double state_rate_ = 10.0;

  mutable std::mutex mutex_;
  MachineState state_;
  ros::Publisher state_pub_;
  ros::Publisher joint_pub_;
  tf2_ros::TransformBroadcaster tf_broadcaster_;
  diagnostic_updater::Updater updater_;
  std::mutex diagnostics_mutex_;  ///< Updater is not thread-safe: the timer and setLink() both run it
  ros::Timer timer_;
  ros::Timer diagnostics_timer_;
  unsigned link_changes_ = 0;
};
}  // namespace cnc_bridge
