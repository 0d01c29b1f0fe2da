// at_controller_node: ROS in the place of the CAM add-in of docs/protocols/at_protocol.md, driving a
// real-time controller over the '@'-protocol (docs/at_controller_node.md). The session with the
// controller (both links, its reports, the motion gate, the commands and the jog deadman, a goal's
// operations) is the core's at_protocol::ControllerSession; a follow_path goal (its operations,
// the program's stops and dwells, a pause by a disable) is carried out by the core's
// at_protocol::GoalRunner; at_protocol::SessionMonitor computes the diagnostics. The node reads
// as parameters -> those core objects -> ROS interfaces:
// src/ros/nodes/at_controller_params.cpp: the parameters; src/ros/nodes/at_controller_node.cpp: the
// session's events, the services and diagnostics; src/ros/nodes/at_controller_goal.cpp: the
// ~follow_path action (goal in, feedback, result, job/path and state out).
#pragma once

#include <geometry_msgs/Point.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "cnc_bridge/AtFollowPathAction.h"
#include "cnc_bridge/AtJog.h"
#include "cnc_bridge/AtSpindle.h"
#include "cnc_bridge/AtToolChange.h"
#include "cnc_bridge/at_protocol/controller_session.h"
#include "cnc_bridge/at_protocol/goal_runner.h"
#include "cnc_bridge/at_protocol/session_monitor.h"
#include "cnc_bridge/ros/machine_frame.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/ros/single_goal_action_server.h"

namespace cnc_bridge
{
namespace at_controller
{
/// ~host, ~tcp_port, ~report_mode, ~report_port, ~listen_port, ~connect_timeout.
at_protocol::TcpLinkSettings linkSettings(const ros::NodeHandle& pnh);

/// The session's options from the parameters (the motion gate's are set by the node).
/// \throws ConfigError naming the parameter that is out of range.
at_protocol::ControllerSession::Options sessionOptions(const ros::NodeHandle& pnh);

/// ~end_tolerance (m, to pulses) and ~end_timeout (s): when a follow_path operation has ended.
/// \throws ConfigError naming the parameter that is out of range.
at_protocol::EndCheck endCheck(const ros::NodeHandle& pnh);

/// Pulses of 1/1000 mm to metres.
geometry_msgs::Point toPoint(const std::array<int32_t, 3>& pulses);
}  // namespace at_controller

class AtControllerNode : public at_protocol::ControllerListener
{
 public:
  AtControllerNode(ros::NodeHandle nh, ros::NodeHandle pnh);
  ~AtControllerNode() override;
  AtControllerNode(const AtControllerNode&) = delete;
  AtControllerNode& operator=(const AtControllerNode&) = delete;

 private:
  class GoalView;

  // ---- the session's events (its link threads, the deadman's) ----------------------------------
  void onLink(LinkState combined, const std::string& why, bool reports_lost) override;
  void onReport(const at_protocol::ReportEvent& event, const at_protocol::ControllerSnapshot& now) override;
  void onReportError(const std::string& what) override;
  void onJogStopped(const at_protocol::JogStop& stop) override;

  // ---- services ---------------------------------------------------------------------------------
  void onMotionSwitched(bool enabled, const std::string& caller);
  bool setAuto(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool jog(AtJog::Request& req, AtJog::Response& res);
  bool spindle(AtSpindle::Request& req, AtSpindle::Response& res);
  bool coolant(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res);
  bool toolChange(AtToolChange::Request& req, AtToolChange::Response& res);
  bool home(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool resume(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);

  // ---- follow_path (at_controller_goal.cpp) -------------------------------------------------------
  void followPath(const AtFollowPathGoalConstPtr& goal);
  at_protocol::GoalOutcome runGoal(const AtFollowPathGoal& goal);
  at_protocol::GoalRequest goalRequest(const AtFollowPathGoal& goal);
  void publishPlannedPath(const std::vector<at_protocol::OperationPlan>& plans);
  void showStarted(const AtFollowPathGoal& goal, const at_protocol::Operation& operation);
  void showEnded(const at_protocol::Job& job);

  // ---- diagnostics --------------------------------------------------------------------------------
  void streamingDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle pnh_;
  std::string report_mode_;
  std::unique_ptr<RuntimeSwitch> motion_;
  std::unique_ptr<ToMachineFrame> to_machine_;  // path goals in other frames
  std::atomic<bool> stopping_{false};

  std::unique_ptr<MachineStatePublisher> state_;
  std::unique_ptr<at_protocol::ControllerSession> session_;
  std::unique_ptr<at_protocol::GoalRunner> goal_runner_;
  std::unique_ptr<at_protocol::SessionMonitor> monitor_;
  SingleGoalActionServer<AtFollowPathAction> follow_path_;
  ros::ServiceServer set_auto_srv_, jog_srv_, spindle_srv_, coolant_srv_, tool_srv_, home_srv_, resume_srv_;
  ros::Publisher path_pub_;
};
}  // namespace cnc_bridge
