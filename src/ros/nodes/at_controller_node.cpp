// at_controller_node: the session's events, the services and diagnostics; main() (see
// at_controller_node.h for the whole node and its files).
#include "at_controller_node.h"

#include <memory>
#include <string>

#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/ros/request_boundary.h"

namespace cnc_bridge
{
namespace ap = at_protocol;

namespace
{
uint8_t toMessage(ap::EStop estop)
{
  return estop == ap::EStop::kOn    ? MachineState::ESTOP_ON
         : estop == ap::EStop::kOff ? MachineState::ESTOP_OFF
                                    : MachineState::ESTOP_UNKNOWN;
}

template <class Response>
bool answer(const ap::Answer& answer, Response& res)
{
  res.success = answer.success;
  res.message = answer.message;
  return true;
}
}  // namespace

geometry_msgs::Point at_controller::toPoint(const std::array<int32_t, 3>& pulses)
{
  geometry_msgs::Point p;
  p.x = pulses[0] / ap::kPulsesPerMetre;
  p.y = pulses[1] / ap::kPulsesPerMetre;
  p.z = pulses[2] / ap::kPulsesPerMetre;
  return p;
}

AtControllerNode::AtControllerNode(ros::NodeHandle nh, ros::NodeHandle pnh)
    : pnh_(pnh),
      follow_path_(
          pnh, "follow_path", [this](const AtFollowPathGoalConstPtr& goal) { followPath(goal); },
          [](const AtFollowPathGoal& goal)
          {
            return goal.gcode_file.empty() ? "path of " + std::to_string(goal.path.poses.size()) + " poses"
                                           : "program " + goal.gcode_file;
          })
{
  const ap::TcpLinkSettings link = at_controller::linkSettings(pnh);
  report_mode_ = link.report_server ? "server" : "client";
  ap::ControllerSession::Options options = at_controller::sessionOptions(pnh);
  const ap::EndCheck end_check = at_controller::endCheck(pnh);
  // ~transform_timeout: s a path goal in another frame waits for its transform into the machine frame.
  to_machine_ = std::make_unique<ToMachineFrame>(params::positive(pnh, "transform_timeout", 0.5));
  if (options.jog_timeout == 0.0)
  {
    ROS_WARN_STREAM("at_controller_node: " << pnh.resolveName("jog_timeout")
                                           << " is 0: the jog deadman is off, a jog goes on until the next jog, "
                                              "set_auto or a disable, even if its client has gone");
  }
  state_ = std::make_unique<MachineStatePublisher>(nh, pnh, link.command.hardwareId());
  // ~enable_motion (start-up value) and ~set_motion_enabled (at run time): nothing that moves
  // axes or turns the spindle is sent unless motion is enabled.
  motion_ = std::make_unique<RuntimeSwitch>(pnh, "motion", "enable_motion", "set_motion_enabled",
                                            [this](bool enabled, const std::string& caller)
                                            { onMotionSwitched(enabled, caller); });
  options.motion = motion_->shared();  // the session acts on its changes (a disable stops what moves)
  state_->diagnostics().add("streaming", this, &AtControllerNode::streamingDiagnostics);
  // job/path: the planned path of the last accepted follow_path goal (latched), for rviz and bags.
  path_pub_ = nh.advertise<nav_msgs::Path>("job/path", 1, true);
  state_->update(
      [&](MachineState& s)
      {
        s.spindle_speed = 0.0;
        // Nothing is known until the controller reports (E0/E1) and an operation sets coolant.
        s.coolant = MachineState::COOLANT_UNKNOWN;
        s.estop = MachineState::ESTOP_UNKNOWN;
        s.execution = MachineState::EXECUTION_UNKNOWN;
      });
  std::string listening_on;
  ap::ControllerLinks links = ap::tcpLinks(link, &listening_on);
  if (link.report_server)
  {
    ROS_INFO_STREAM("at_controller_node: waiting for the controller's reports on " << listening_on);
  }
  session_ = std::make_unique<ap::ControllerSession>(std::move(links), options, this);
  monitor_ = std::make_unique<ap::SessionMonitor>(*session_);  // before start(): a link change updates diagnostics
  session_->start();
  goal_runner_ = std::make_unique<ap::GoalRunner>(
      *session_,
      ap::GoalRunner::Names{pnh.resolveName("resume"), pnh.resolveName("set_motion_enabled"),
                            pnh.resolveName("optional_stop"), pnh.resolveName("end_tolerance"),
                            pnh.resolveName("end_timeout")},
      end_check);

  set_auto_srv_ = advertiseGuardedService(pnh, "set_auto", &AtControllerNode::setAuto, this);
  jog_srv_ = advertiseGuardedService(pnh, "jog", &AtControllerNode::jog, this);
  spindle_srv_ = advertiseGuardedService(pnh, "spindle", &AtControllerNode::spindle, this);
  coolant_srv_ = advertiseGuardedService(pnh, "coolant", &AtControllerNode::coolant, this);
  tool_srv_ = advertiseGuardedService(pnh, "tool_change", &AtControllerNode::toolChange, this);
  home_srv_ = advertiseGuardedService(pnh, "home", &AtControllerNode::home, this);
  resume_srv_ = advertiseGuardedService(pnh, "resume", &AtControllerNode::resume, this);
  follow_path_.start();
}

AtControllerNode::~AtControllerNode()
{
  stopping_ = true;
  // A goal in progress is cancelled (decelerates to a stop) and its thread joined while the
  // session it uses still runs.
  follow_path_.shutdown();
  goal_runner_->wake();
  session_->stop();
}

// ---- the session's events (its link threads, the deadman's) -----------------------------------------

void AtControllerNode::onLink(LinkState combined, const std::string& why, bool reports_lost)
{
  state_->setLink(combined, why);
  if (reports_lost)
  {
    state_->update([](MachineState& s) { s.estop = MachineState::ESTOP_UNKNOWN; });
  }
}

void AtControllerNode::onReport(const ap::ReportEvent& event, const ap::ControllerSnapshot& now)
{
  using Kind = ap::ReportEvent::Kind;
  if (event.kind == Kind::kPosition)
  {
    // Pulses of 1/1000 mm to metres.
    const geometry_msgs::Point p = at_controller::toPoint(now.position);
    state_->setPosition(p.x, p.y, p.z);
    return;
  }
  state_->update(
      [&](MachineState& s)
      {
        s.message = event.message;
        if (event.kind == Kind::kEStop)
        {
          s.estop = toMessage(now.estop);
          s.execution = now.estop == ap::EStop::kOn ? MachineState::EXECUTION_ALARM : MachineState::EXECUTION_READY;
        }
        else if (event.kind == Kind::kMode)
        {
          s.mode = now.jog_axis >= 0 ? MachineState::MODE_MANUAL : MachineState::MODE_AUTO;
        }
      });
}

void AtControllerNode::onReportError(const std::string& what)
{
  ROS_WARN_STREAM_THROTTLE(5.0, "at_controller_node: " << what);
}

/// The deadman's stop of a jog with no ~jog call for ~jog_timeout (feed 0, as a disable sends).
void AtControllerNode::onJogStopped(const ap::JogStop& stop)
{
  if (stop.sent)
  {
    ROS_WARN_STREAM("at_controller_node: " << stop.why << " (" << pnh_.resolveName("jog_timeout") << "): sent F0@");
  }
  else
  {
    ROS_ERROR_STREAM("at_controller_node: " << stop.why << ", but feed 0 could not be sent: " << stop.failure);
  }
  state_->update([&](MachineState& s)
                 { s.message = stop.sent ? stop.why : stop.why + " (feed 0 not sent: " + stop.failure + ")"; });
}

// ---- services ------------------------------------------------------------------------------------

/// ~set_motion_enabled: says so in state; the session, a listener of the same switch, stops what
/// moves (a running path decelerates along the path to a stop and holds, its goal paused until
/// enabled and ~resume; a jog gets feed 0).
void AtControllerNode::onMotionSwitched(bool enabled, const std::string& caller)
{
  state_->update([&](MachineState& s)
                 { s.message = std::string("motion ") + (enabled ? "enabled" : "disabled") + " by " + caller; });
}

bool AtControllerNode::setAuto(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
{
  return answer(session_->setAuto(), res);
}

/// A moving jog arms the session's deadman for ~jog_timeout, feed 0 disarms it.
bool AtControllerNode::jog(AtJog::Request& req, AtJog::Response& res)
{
  return answer(session_->jog(req.axis, req.feed_rate), res);
}

bool AtControllerNode::spindle(AtSpindle::Request& req, AtSpindle::Response& res)
{
  double rpm = 0.0;
  answer(session_->spindle(req.speed, &rpm), res);
  if (res.success)
  {
    state_->update([&](MachineState& s) { s.spindle_speed = rpm; });
  }
  return true;
}

bool AtControllerNode::coolant(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res)
{
  // The protocol switches coolant only with an operation (P1@ / P0@, steps 5-6 and 16).
  session_->setCoolant(req.data);
  res.success = true;
  res.message = std::string("coolant ") + (req.data ? "on (P1@)" : "off (P0@)") +
                " for the next operations; the protocol has no coolant command outside an operation";
  return true;
}

bool AtControllerNode::toolChange(AtToolChange::Request& req, AtToolChange::Response& res)
{
  answer(session_->toolChange(req.tool, req.length), res);
  if (res.success)
  {
    state_->update([&](MachineState& s) { s.tool = req.tool; });
  }
  return true;
}

bool AtControllerNode::home(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
{
  return answer(session_->home(), res);
}

/// ~resume: a goal held at the program's M00/M01, or paused because motion was disabled, goes
/// on, if motion may start (enabled, e-stop released).
bool AtControllerNode::resume(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
{
  return answer(goal_runner_->resume(), res);
}

// ---- diagnostics ---------------------------------------------------------------------------------

/// The session monitor's report as it is, the motion switch and the report mode.
void AtControllerNode::streamingDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  const ap::SessionMonitor::Report report = monitor_->report();
  status.summary(report.level == ap::SessionMonitor::Level::kError  ? diagnostic_msgs::DiagnosticStatus::ERROR
                 : report.level == ap::SessionMonitor::Level::kWarn ? diagnostic_msgs::DiagnosticStatus::WARN
                                                                    : diagnostic_msgs::DiagnosticStatus::OK,
                 report.summary);
  for (const auto& [key, value] : report.streaming)
  {
    status.add(key, value);
  }
  motion_->addTo(status);
  for (const auto& [key, value] : report.controller)
  {
    status.add(key, value);
  }
  status.add("report mode", report_mode_);
}
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::AtControllerNode>(argc, argv, "at_controller_node");
}
