// dnc_node: NC program transfer between ~program_dir and a control's RS-232 port (see dnc_node.h
// and docs/dnc_node.md). This file builds the node from its settings (read in dnc_params.cpp):
// the core session that runs the transfers (cnc_bridge/dnc/transfer_session.h), the motion
// switch that gates a drip-feed, and shows what the session reports as state, diagnostics and
// program_requests. The action and services are in dnc_transfer_action.cpp, the drip-feed's
// ROS side in dnc_drip_handlers.cpp.
#include "dnc_node.h"

#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/request_boundary.h"
#include "dnc_drip_handlers.h"

namespace cnc_bridge
{
namespace
{
uint8_t executionOf(dnc::Execution execution)
{
  switch (execution)
  {
    case dnc::Execution::kReady:
      return MachineState::EXECUTION_READY;
    case dnc::Execution::kActive:
      return MachineState::EXECUTION_ACTIVE;
    case dnc::Execution::kPaused:
      return MachineState::EXECUTION_PAUSED;
    case dnc::Execution::kStopped:
      break;
  }
  return MachineState::EXECUTION_STOPPED;
}
}  // namespace

DncNode::DncNode(ros::NodeHandle nh, ros::NodeHandle pnh) : DncNode(nh, pnh, dncSettings(pnh)) {}

DncNode::DncNode(ros::NodeHandle nh, ros::NodeHandle pnh, const dnc::DncSettings& settings) : nh_(nh), pnh_(pnh)
{
  const dnc::TransferSettings& transfer = settings.transfer;
  state_ = std::make_unique<MachineStatePublisher>(nh, pnh, transfer.link.hardwareId());
  // ~enable_motion (bool, default false) and ~set_motion_enabled: a drip-feed (a goal or a
  // control's request answered by drip) runs the program on the control as it arrives.
  motion_ = std::make_unique<RuntimeSwitch>(pnh, "motion", "enable_motion", "set_motion_enabled");
  requests_pub_ = nh.advertise<ProgramRequestEvent>("program_requests", 20);

  dnc::SessionParts parts;
  parts.listener = this;
  parts.motion = &motion_->core();
  parts.machine = state_->machineName();
  parts.cancel_topic = pnh.resolveName("transfer") + "/cancel";
  session_ = std::make_unique<dnc::TransferSession>(transfer, settings.requests, std::move(parts));

  state_->update(
      [&](MachineState& s)
      {
        s.mode = MachineState::MODE_DNC;
        s.execution = MachineState::EXECUTION_READY;
      });
  state_->setLink(LinkState::kDown, "port opened on demand");
  state_->diagnostics().add("Transfers", this, &DncNode::transferDiagnostics);
  // DNC drip-feed (drip) and program backup (backup): ~pause, ~resume, ~plan_drip,
  // dnc/current_line (docs/dnc_drip_feed.md).
  registerDripProtocols(*session_, nh, pnh, settings.drip, *state_);
  // The kept-open port, and the program requests punched by the control (~requests, ~request_mode).
  session_->start();

  send_srv_ = advertiseGuardedService(pnh, "send_program", &DncNode::onSend, this);
  receive_srv_ = advertiseGuardedService(pnh, "receive_program", &DncNode::onReceive, this);
  // ~transfer: a goal arriving while a transfer runs is rejected with the reason, the running one
  // goes on (dnc_transfer_action.cpp).
  startTransferAction();
  ROS_INFO("dnc_node on %s, programs in %s, default protocol %s", transfer.link.serial.describe().c_str(),
           session_->programs().root().c_str(), session_->defaultProtocol().c_str());
}

DncNode::~DncNode()
{
  session_->stop();
  action_.reset();  // waits for the running goal to end
}

void DncNode::onLink(LinkState state, const std::string& message)
{
  state_->setLink(state, message);
}

void DncNode::onState(const dnc::StateChange& change)
{
  state_->update(
      [&](MachineState& s)
      {
        if (change.execution)
          s.execution = executionOf(*change.execution);
        if (change.program)
          s.program = *change.program;
        if (change.block)
          s.block = *change.block;
        if (change.message)
          s.message = *change.message;
      });
}

void DncNode::onRequest(const dnc::RequestEvent& request)
{
  ProgramRequestEvent event;
  event.header.stamp = ros::Time::now();
  event.machine = state_->machineName();
  event.source = "rs232 " + session_->device();
  event.request = request.request;
  event.number = request.number;
  event.program = request.program;
  event.outcome = request.outcome;
  event.success = request.success;
  requests_pub_.publish(event);
}

void DncNode::transferDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  const dnc::TransferTotals totals = session_->totals();
  if (totals.lastFailed())
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "last transfer failed: " + totals.last_result);
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK,
                   totals.last_result.empty() ? "no transfer yet" : totals.last_result);
  for (const auto& [name, value] : totals.fields(session_->requestsEnabled()))
    status.add(name, value);
  status.add("default protocol", session_->defaultProtocol());
  status.add("program_dir", session_->programs().root());
}
}  // namespace cnc_bridge

// Four threads: a service call may run a whole transfer; keep serving meanwhile.
int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::DncNode>(argc, argv, "dnc_node", {4});
}
