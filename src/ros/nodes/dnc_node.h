// dnc_node: NC programs to and from a control over its RS-232 port. The transfers are the core's
// dnc::TransferSession (cnc_bridge/dnc/transfer_session.h: the serial link opened per transfer or
// kept open, the port lock, one transfer at a time, the protocol handlers, the counters, the
// archive, the program requests the control punches); the drip and backup protocols its
// dnc::DripProtocols. The node reads its parameters in one place (dnc_params.cpp) and maps the
// session to ROS: the ~transfer action and the ~send_program / ~receive_program services
// (dnc_transfer_action.cpp; a ~transfer goal sent while a transfer runs is rejected with the
// reason, never preempts the running one), state and diagnostics, program_requests (this file's
// source), and the drip-feed's services and dnc/current_line (dnc_drip_handlers.cpp).
#pragma once

#include <ros/ros.h>

#include <memory>
#include <string>

#include "cnc_bridge/ProgramRequestEvent.h"
#include "cnc_bridge/ReceiveProgram.h"
#include "cnc_bridge/SendProgram.h"
#include "cnc_bridge/TransferAction.h"
#include "cnc_bridge/dnc/dnc_settings.h"
#include "cnc_bridge/dnc/transfer_session.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/ros/single_goal_action_server.h"

namespace cnc_bridge
{
/// \brief dnc_node's parameters as settings (dnc_params.cpp). \throws ConfigError naming a bad one.
dnc::DncSettings dncSettings(const ros::NodeHandle& pnh);

/// \brief The dnc_node. Services and the action may be called from any spinner thread.
class DncNode : private dnc::TransferListener
{
 public:
  DncNode(ros::NodeHandle nh, ros::NodeHandle pnh);
  DncNode(ros::NodeHandle nh, ros::NodeHandle pnh, const dnc::DncSettings& settings);
  ~DncNode() override;

 private:
  // dnc::TransferListener: the session's link, state and requests shown.
  void onLink(LinkState state, const std::string& message) override;
  void onState(const dnc::StateChange& change) override;
  void onRequest(const dnc::RequestEvent& event) override;

  /// Starts ~transfer: a goal is admitted once it has reserved the port (TransferSession::tryReserve()).
  void startTransferAction();
  /// Runs an admitted goal (the port reserved for it) and ends it.
  void executeGoal(const TransferGoal& goal);
  bool onSend(SendProgram::Request& request, SendProgram::Response& response);
  bool onReceive(ReceiveProgram::Request& request, ReceiveProgram::Response& response);
  void transferDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_;
  ros::NodeHandle pnh_;
  std::unique_ptr<MachineStatePublisher> state_;
  std::unique_ptr<RuntimeSwitch> motion_;  ///< gates drip-feeds (~enable_motion)
  ros::Publisher requests_pub_;
  std::unique_ptr<dnc::TransferSession> session_;
  std::unique_ptr<SingleGoalActionServer<TransferAction>> action_;  ///< ~transfer
  ros::ServiceServer send_srv_;
  ros::ServiceServer receive_srv_;
};
}  // namespace cnc_bridge
