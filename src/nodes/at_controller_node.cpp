// at_controller_node: ROS in the place of the CAM add-in of docs/protocols/at_protocol.md, driving a
// real-time controller over the '@'-protocol (docs/at_controller_node.md). The session with the
// controller (both links, its reports, the motion gate, the commands, a goal's operations) is the
// core's at_protocol::ControllerSession; this class maps parameters to it and it to ROS: services
// and the ~follow_path action in, state, joint_states, tf, job/path and diagnostics out.
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>

#include <cmath>
#include <condition_variable>
#include <memory>
#include <sstream>

#include "cnc_bridge/AtFollowPathAction.h"
#include "cnc_bridge/AtJog.h"
#include "cnc_bridge/AtSpindle.h"
#include "cnc_bridge/AtToolChange.h"
#include "cnc_bridge/at_protocol/controller_session.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/gcode/program_steps.h"
#include "cnc_bridge/ros/gcode_params.h"
#include "cnc_bridge/ros/machine_frame.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/ros/single_goal_action_server.h"

namespace cnc_bridge
{
namespace ap = at_protocol;

namespace
{
/// ~host, ~tcp_port, ~report_mode, ~report_port, ~listen_port, ~connect_timeout.
ap::TcpLinkSettings linkSettings(const ros::NodeHandle& pnh)
{
  ap::TcpLinkSettings link;
  // ~host: address of the controller (both sockets in client mode).
  link.host = pnh.param<std::string>("host", "127.0.0.1");
  // ~tcp_port: the controller's command server (the paper's server_recv).
  link.command_port = params::tcpPort(pnh, "tcp_port", 5000);
  // ~report_mode: "client" connects to the controller's report server (the paper's server_send,
  // like the add-in's ReceiveClient); "server" listens on ~listen_port for the controller.
  link.report_server = params::choice(pnh, "report_mode", "client", {"client", "server"}) == "server";
  // ~report_port: the controller's report server (client mode).
  link.report_port = params::tcpPort(pnh, "report_port", 5001);
  // ~listen_port: our report server (server mode); 0 picks a free port (logged).
  link.listen_port = params::tcpPort(pnh, "listen_port", 5001, params::PortZero::kMeansAny);
  // ~connect_timeout: s allowed for one TCP connect.
  link.connect_timeout = params::seconds(pnh, "connect_timeout", 2.0);
  return link;
}

/// ~period, ~max_speed_x/y/z (m/s; also the speed a feed value of 255 stands for), ~max_accel_x/y/z
/// (m/s^2), ~corner_share, ~profile (trapezoid, or scurve: jerk-limited by ~max_jerk_x/y/z, m/s^3).
/// The planner works in mm (the machinist's unit): m * 1000.
ap::PlannerLimits plannerLimits(const ros::NodeHandle& pnh)
{
  ap::PlannerLimits limits;
  limits.period = params::positive(pnh, "period", 0.001);  // s, the controller's time loop
  const char* axes[] = {"x", "y", "z"};
  const double speed[] = {0.05, 0.05, 0.025}, accel[] = {0.5, 0.5, 0.25}, jerk[] = {10.0, 10.0, 5.0};
  for (int i = 0; i < 3; ++i)
  {
    limits.max_speed[i] = params::positive(pnh, std::string("max_speed_") + axes[i], speed[i]) * 1000.0;
    limits.max_accel[i] = params::positive(pnh, std::string("max_accel_") + axes[i], accel[i]) * 1000.0;
  }
  pnh.param("corner_share", limits.corner_share, 0.2);
  const std::string profile = pnh.param<std::string>("profile", "trapezoid");
  if (profile != "trapezoid" && profile != "scurve")
  {
    throw ConfigError(pnh.resolveName("profile") + " must be trapezoid or scurve, not '" + profile + "'");
  }
  limits.profile = profile == "scurve" ? ap::Profile::kSCurve : ap::Profile::kTrapezoid;
  for (int i = 0; i < 3; ++i)
  {
    limits.max_jerk[i] = params::positive(pnh, std::string("max_jerk_") + axes[i], jerk[i]) * 1000.0;
  }
  limits.validate();
  return limits;
}

/// The session's options from the parameters (the motion gate's are set by the node).
ap::ControllerSession::Options sessionOptions(const ros::NodeHandle& pnh)
{
  ap::ControllerSession::Options options;
  // ~program_dir: directory G-code goals are read from; empty refuses G-code goals.
  options.program_dir = pnh.param<std::string>("program_dir", "");
  options.program_dir_setting = pnh.resolveName("program_dir");
  options.limits = plannerLimits(pnh);
  // ~default_feed_rate: m/s along the path when neither the goal nor the program gives one.
  options.default_feed = params::positive(pnh, "default_feed_rate", 0.01);
  // ~gcode_dialect (haas, fanuc or linuxcnc, docs/gcode.md); ~tool_table: diameters for G41/G42.
  params::gcodeOptions(pnh, options.gcode);
  // ~spindle_max_rpm: rev/min that the spindle value 255 stands for.
  options.spindle_max_rpm = params::positive(pnh, "spindle_max_rpm", 24000.0);
  // ~coolant: whether operations use coolant (P1@) unless a goal says otherwise; ~coolant service.
  options.coolant = pnh.param("coolant", false);
  // ~realtime_priority: SCHED_FIFO priority of the 1 ms sender thread (with locked memory), 50 by
  // default: the priority of the kernel's threaded interrupt handlers on PREEMPT_RT, so no
  // ordinary thread delays a setpoint while device interrupts still come first. 0 keeps the
  // normal scheduler; where real time is not permitted the sender falls back to it with one
  // warning naming what allows it.
  options.sender.realtime_priority = pnh.param("realtime_priority", 50);
  options.sender.write_timeout = params::seconds(pnh, "write_timeout", 0.2);
  // ~jog_timeout: s a jog moves after its last ~jog call (the deadman, as teleoperation commands
  // have one); a client renews it by calling ~jog again. 0 turns the deadman off.
  options.jog_timeout = pnh.param("jog_timeout", 0.5);
  if (!(options.jog_timeout >= 0.0))
  {
    throw ConfigError(pnh.resolveName("jog_timeout") + " must be 0 (no deadman) or a positive number of seconds");
  }
  return options;
}

geometry_msgs::Point toPoint(const std::array<int32_t, 3>& pulses)
{
  geometry_msgs::Point p;
  p.x = pulses[0] / ap::kPulsesPerMetre;
  p.y = pulses[1] / ap::kPulsesPerMetre;
  p.z = pulses[2] / ap::kPulsesPerMetre;
  return p;
}

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

class AtControllerNode : public ap::ControllerListener
{
 public:
  AtControllerNode(ros::NodeHandle nh, ros::NodeHandle pnh)
      : pnh_(pnh),
        follow_path_(
            pnh, "follow_path", [this](const AtFollowPathGoalConstPtr& goal) { followPath(goal); },
            [](const AtFollowPathGoal& goal)
            {
              return goal.gcode_file.empty() ? "path of " + std::to_string(goal.path.poses.size()) + " poses"
                                             : "program " + goal.gcode_file;
            })
  {
    const ap::TcpLinkSettings link = linkSettings(pnh);
    report_mode_ = link.report_server ? "server" : "client";
    ap::ControllerSession::Options options = sessionOptions(pnh);
    // ~transform_timeout: s a path goal in another frame waits for its transform into the machine frame.
    to_machine_ = std::make_unique<ToMachineFrame>(params::positive(pnh, "transform_timeout", 0.5));
    if (options.jog_timeout == 0.0)
    {
      ROS_WARN_STREAM("at_controller_node: " << pnh.resolveName("jog_timeout")
                                             << " is 0: the jog deadman is off, a jog goes on until the next jog, "
                                                "set_auto or a disable, even if its client has gone");
    }
    // One-shot, started by each jog; a steady clock, so a change of the system time cannot stop or delay it.
    jog_timer_ = nh.createSteadyTimer(ros::WallDuration(std::max(options.jog_timeout, 0.001)),
                                      &AtControllerNode::onJogTimer, this, true, false);
    state_ = std::make_unique<MachineStatePublisher>(nh, pnh, link.host + ":" + std::to_string(link.command_port));
    // ~enable_motion (start-up value) and ~set_motion_enabled (at run time): nothing that moves
    // axes or turns the spindle is sent unless motion is enabled.
    motion_ = std::make_unique<RuntimeSwitch>(pnh, "motion", "enable_motion", "set_motion_enabled",
                                              [this](bool enabled, const std::string& caller)
                                              { onMotionSwitched(enabled, caller); });
    options.motion_enabled = motion_->enabled();
    options.disabled_refusal = [this](const std::string& what) { return motion_->refusal(what); };
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
    session_->start();

    set_auto_srv_ = pnh.advertiseService("set_auto", &AtControllerNode::setAuto, this);
    jog_srv_ = pnh.advertiseService("jog", &AtControllerNode::jog, this);
    spindle_srv_ = pnh.advertiseService("spindle", &AtControllerNode::spindle, this);
    coolant_srv_ = pnh.advertiseService("coolant", &AtControllerNode::coolant, this);
    tool_srv_ = pnh.advertiseService("tool_change", &AtControllerNode::toolChange, this);
    home_srv_ = pnh.advertiseService("home", &AtControllerNode::home, this);
    resume_srv_ = pnh.advertiseService("resume", &AtControllerNode::resume, this);
    follow_path_.start();
  }

  ~AtControllerNode() override
  {
    stopping_ = true;
    jog_timer_.stop();
    // A goal in progress is cancelled (decelerates to a stop) and its thread joined while the
    // session it uses still runs.
    follow_path_.shutdown();
    hold_cv_.notify_all();
    session_->stop();
  }

 private:
  // ---- the session's events (its link threads) --------------------------------------------------

  void onLink(LinkState combined, const std::string& why, bool reports_lost) override
  {
    state_->setLink(combined, why);
    if (reports_lost)
    {
      state_->update([](MachineState& s) { s.estop = MachineState::ESTOP_UNKNOWN; });
    }
  }

  void onReport(const ap::ReportEvent& event, const ap::ControllerSnapshot& now) override
  {
    using Kind = ap::ReportEvent::Kind;
    if (event.kind == Kind::kPosition)
    {
      // Pulses of 1/1000 mm to metres.
      const geometry_msgs::Point p = toPoint(now.position);
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

  void onReportError(const std::string& what) override
  {
    ROS_WARN_STREAM_THROTTLE(5.0, "at_controller_node: " << what);
  }

  // ---- services ---------------------------------------------------------------------------------

  /// ~set_motion_enabled: disabling stops what moves (a running path decelerates along the path to
  /// a stop and holds, its goal paused until enabled and ~resume; a jog gets feed 0) and says so in
  /// state.
  void onMotionSwitched(bool enabled, const std::string& caller)
  {
    state_->update([&](MachineState& s)
                   { s.message = std::string("motion ") + (enabled ? "enabled" : "disabled") + " by " + caller; });
    session_->setMotionEnabled(enabled, caller);
  }

  bool setAuto(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    return answer(session_->setAuto(), res);
  }

  bool jog(AtJog::Request& req, AtJog::Response& res)
  {
    answer(session_->jog(req.axis, req.feed_rate), res);
    ap::Deadman& deadman = session_->jogDeadman();
    if (res.success && deadman.enabled())
    {
      // A moving jog (re)armed the deadman for ~jog_timeout, feed 0 disarmed it.
      jog_timer_.stop();
      if (deadman.armed())
      {
        jog_timer_.setPeriod(ros::WallDuration(std::chrono::duration<double>(deadman.timeout()).count()));
        jog_timer_.start();
      }
    }
    return true;
  }

  /// The deadman's timer: a jog with no ~jog call for ~jog_timeout gets feed 0 (as a disable does).
  void onJogTimer(const ros::SteadyTimerEvent&)
  {
    ap::Deadman::Clock::duration remaining{};
    const std::optional<ap::JogStop> stop = session_->expireJog(ap::Deadman::Clock::now(), &remaining);
    if (!stop)
    {
      if (remaining > ap::Deadman::Clock::duration::zero())
      {
        // Woken before the deadline (the clocks of the timer and the deadman differ slightly).
        jog_timer_.stop();
        jog_timer_.setPeriod(ros::WallDuration(std::chrono::duration<double>(remaining).count()));
        jog_timer_.start();
      }
      return;
    }
    {
      std::lock_guard<std::mutex> lock(jog_stop_mutex_);
      last_jog_stop_ = stop->sent ? stop->why : stop->why + ", but feed 0 could not be sent: " + stop->failure;
    }
    if (stop->sent)
    {
      ROS_WARN_STREAM("at_controller_node: " << stop->why << " (" << pnh_.resolveName("jog_timeout") << "): sent F0@");
    }
    else
    {
      ROS_ERROR_STREAM("at_controller_node: " << stop->why << ", but feed 0 could not be sent: " << stop->failure);
    }
    state_->update([&](MachineState& s)
                   { s.message = stop->sent ? stop->why : stop->why + " (feed 0 not sent: " + stop->failure + ")"; });
  }

  bool spindle(AtSpindle::Request& req, AtSpindle::Response& res)
  {
    double rpm = 0.0;
    answer(session_->spindle(req.speed, &rpm), res);
    if (res.success)
    {
      state_->update([&](MachineState& s) { s.spindle_speed = rpm; });
    }
    return true;
  }

  bool coolant(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res)
  {
    // The protocol switches coolant only with an operation (P1@ / P0@, steps 5-6 and 16).
    session_->setCoolant(req.data);
    res.success = true;
    res.message = std::string("coolant ") + (req.data ? "on (P1@)" : "off (P0@)") +
                  " for the next operations; the protocol has no coolant command outside an operation";
    return true;
  }

  bool toolChange(AtToolChange::Request& req, AtToolChange::Response& res)
  {
    answer(session_->toolChange(req.tool, req.length), res);
    if (res.success)
    {
      state_->update([&](MachineState& s) { s.tool = req.tool; });
    }
    return true;
  }

  bool home(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) { return answer(session_->home(), res); }

  // ---- follow_path --------------------------------------------------------------------------------

  using Plan = ap::OperationPlan;

  /// The goal without ROS types: a path's poses in the machine frame (a pose names its frame, else
  /// the path's; empty means the machine frame), in metres.
  ap::GoalRequest goalRequest(const AtFollowPathGoal& goal)
  {
    ap::GoalRequest request;
    request.gcode_file = goal.gcode_file;
    request.has_path = !goal.path.poses.empty();
    request.feed_rate = goal.feed_rate;
    request.coolant = goal.coolant;
    request.spindle_speed = goal.spindle_speed;
    request.tool = goal.tool;
    request.tool_length = goal.tool_length;
    for (const auto& stamped : goal.gcode_file.empty() ? goal.path.poses : decltype(goal.path.poses){})
    {
      const std::string& frame = stamped.header.frame_id.empty() ? goal.path.header.frame_id : stamped.header.frame_id;
      const geometry_msgs::Pose pose =
          ToMachineFrame::apply(to_machine_->lookup(state_->frame("machine"), frame, "path"), stamped.pose);
      request.path_m.push_back({pose.position.x, pose.position.y, pose.position.z});
    }
    return request;
  }

  /// Publishes the planned corners (pulses) of every operation as job/path in <tf_prefix>machine, metres.
  void publishPlannedPath(const std::vector<Plan>& plans)
  {
    nav_msgs::Path path;
    path.header.stamp = ros::Time::now();
    path.header.frame_id = state_->frame("machine");
    for (size_t p = 0; p < plans.size(); ++p)
    {
      // Each operation starts where the one before ended: that corner once.
      for (size_t i = p == 0 ? 0 : 1; i < plans[p].points.size(); ++i)
      {
        geometry_msgs::PoseStamped pose;
        pose.header = path.header;
        pose.pose.position.x = plans[p].points[i][0] / ap::kPulsesPerMetre;
        pose.pose.position.y = plans[p].points[i][1] / ap::kPulsesPerMetre;
        pose.pose.position.z = plans[p].points[i][2] / ap::kPulsesPerMetre;
        pose.pose.orientation.w = 1.0;
        path.poses.push_back(pose);
      }
    }
    path_pub_.publish(path);
  }

  void followPath(const AtFollowPathGoalConstPtr& goal)
  {
    AtFollowPathResult result;
    const auto abort = [&](const std::string& why)
    {
      result.success = false;
      result.message = why;
      ROS_WARN_STREAM("at_controller_node: follow_path: " << why);
      follow_path_.setAborted(result, why);
    };
    std::string refusal = session_->motionRefusal("follow_path");
    if (!refusal.empty())
    {
      return abort(refusal);
    }
    const ap::ControllerSnapshot now = session_->snapshot();
    if (!now.position_valid)
    {
      return abort("the controller has not reported its position yet (is the report link up?)");
    }
    try
    {
      // ~program_commands is read at each goal.
      const std::vector<Plan> plans =
          session_->planGoal(goalRequest(*goal), now.position, pnh_.param("program_commands", false),
                             pnh_.resolveName("program_commands"));
      publishPlannedPath(plans);  // before motion: the path is known once the goal is accepted
      AtFollowPathFeedback feedback;
      std::string end_note;
      for (const Plan& plan : plans)
      {
        if (plan.moves() && !runPlan(*goal, plan, result, feedback))
        {
          return;  // cancelled or failed: the goal has ended
        }
        if (plan.after)
        {
          if (plan.after->kind == gcode::ProgramStep::Kind::kEnd)
          {
            end_note = plan.after->describe() + ": the program ends here; nothing after it was sent";
            break;
          }
          if (!carryOut(*plan.after, feedback))
          {
            return endCancelled(result, "cancelled at the " + plan.after->describe());
          }
        }
      }
      result.success = true;
      if (!end_note.empty())
      {
        result.message = end_note;
        state_->update([&](MachineState& s) { s.message = "follow_path: " + end_note; });
      }
      follow_path_.setSucceeded(result, result.message);
    }
    catch (const std::exception& e)
    {
      abort(e.what());
    }
  }

  /// Ends the goal PREEMPTED (a cancel while nothing moves: nothing more is sent).
  void endCancelled(AtFollowPathResult& result, const std::string& message)
  {
    result.message = message;
    state_->update(
        [&](MachineState& s)
        {
          s.execution = MachineState::EXECUTION_STOPPED;
          s.message = result.message;
        });
    follow_path_.setPreempted(result, result.message);
  }

  /// Runs one operation of a goal. Motion disabled before or during it pauses the goal (the path
  /// decelerates to a stop and holds, the goal stays active) until motion is enabled and ~resume
  /// is called; the rest of the path is then planned from the stop point, from rest, to its end.
  /// \returns true if the operation reached its end (the goal goes on); otherwise the goal has
  /// ended (cancelled, e-stop, link failure).
  bool runPlan(const AtFollowPathGoal& goal, const Plan& plan, AtFollowPathResult& result,
               AtFollowPathFeedback& feedback)
  {
    Plan rest = plan;
    for (;;)
    {
      while (!session_->motionEnabled())
      {
        // Disabled between operations (during a dwell or a program stop): nothing is moving.
        const std::string by = session_->motionDisabledBy();
        const std::string event =
            "motion disabled by " + by + " (" + pnh_.resolveName("set_motion_enabled") + ") before the next operation";
        if (!holdUntilResume("stop when motion was disabled by " + by, event, feedback))
        {
          endCancelled(result, "cancelled while held: " + event);
          return false;
        }
      }
      const std::string refusal = session_->motionRefusal("follow_path");
      if (!refusal.empty())
      {
        // The e-stop (E1 or unknown) between operations: the goal cannot go on.
        result.message =
            refusal + (feedback.event.empty() ? "" : " (before the operation after " + feedback.event + ")");
        ROS_WARN_STREAM("at_controller_node: follow_path: " << result.message);
        follow_path_.setAborted(result, result.message);
        return false;
      }
      std::optional<ap::DisabledStop> stop;
      if (runOperation(goal, rest, result, feedback, stop))
      {
        return true;
      }
      if (!stop)
      {
        return false;  // cancelled, e-stop or link failure: the goal has ended
      }
      std::ostringstream event;
      event << "motion disabled by " << stop->by << " (" << pnh_.resolveName("set_motion_enabled")
            << "): decelerated to a stop along the path at X" << stop->position[0] / ap::kPulsesPerMm << " Y"
            << stop->position[1] / ap::kPulsesPerMm << " Z" << stop->position[2] / ap::kPulsesPerMm << " mm after "
            << stop->sent << " of " << stop->planned << " planned setpoints";
      ROS_WARN_STREAM("at_controller_node: follow_path: " << event.str() << "; holding");
      if (!holdUntilResume("stop when motion was disabled by " + stop->by, event.str(), feedback))
      {
        endCancelled(result, "cancelled while held: " + event.str());
        return false;
      }
      const ap::PathRest left = ap::restOfPath(rest.points, rest.feeds, stop->distance, stop->position);
      if (left.empty())
      {
        return true;  // it came to rest on the end point
      }
      rest.points = left.points;
      rest.feeds = left.feeds;
      rest.tool = -1;  // the tool was changed before the stop
    }
  }

  /// Runs one operation to its end. \returns true if it succeeded (the goal goes on). Otherwise
  /// either \p stop says where motion was disabled (the operation decelerated to a stop and ended
  /// with #@ M0@; the goal goes on, paused) or the goal has been ended (cancelled, e-stop, link
  /// failure).
  bool runOperation(const AtFollowPathGoal& goal, const Plan& plan, AtFollowPathResult& result,
                    AtFollowPathFeedback& feedback, std::optional<ap::DisabledStop>& stop)
  {
    const ap::Operation operation = session_->operationFor(plan, goal.tool, goal.tool_length);
    // The S-curve streams the trapezoid's steps plus its average's window less one.
    const size_t setpoints = ap::TrajectoryStream(*operation.trajectory).total();
    const double period = session_->options().limits.period;
    ROS_INFO_STREAM("at_controller_node: follow_path: "
                    << plan.points.size() - 1 << " segments, " << operation.trajectory->length() / ap::kPulsesPerMm
                    << " mm in " << setpoints * period << " s (" << setpoints << " setpoints)");
    ap::ControllerSession::OperationWatch watch;
    watch.started = [&](const ap::Job&) { showStarted(goal, operation); };
    watch.cancel_requested = [this] { return follow_path_.isPreemptRequested() || !ros::ok() || stopping_; };
    watch.progress = [&](const ap::Job& job, bool stopping) { publishFeedback(job, stopping, feedback); };
    feedback.paused = false;
    const ap::OperationResult run = session_->runOperation(plan, operation, watch);
    const ap::Job& job = *run.job;
    result.setpoints += job.sent();
    result.underruns += static_cast<uint32_t>(run.underruns);
    const ap::ControllerSnapshot now = session_->snapshot();
    result.final_position = toPoint(now.position);
    result.message = job.message();
    state_->update(
        [&](MachineState& s)
        {
          s.execution = now.estop == ap::EStop::kOn                 ? MachineState::EXECUTION_ALARM
                        : job.state() == ap::Job::State::kSucceeded ? MachineState::EXECUTION_READY
                                                                    : MachineState::EXECUTION_STOPPED;
          s.mode = now.jog_axis >= 0 ? MachineState::MODE_MANUAL : MachineState::MODE_AUTO;
          s.coolant = MachineState::COOLANT_OFF;  // #@ ends the operation's coolant
          s.spindle_speed = 0.0;                  // M0@ stops the spindle (step 18)
          s.message = "follow_path " + std::string(ap::Job::toString(job.state())) + ": " + job.message();
        });
    stop = run.disabled;
    if (stop)
    {
      return false;
    }
    switch (job.state())
    {
      case ap::Job::State::kSucceeded:
        return true;
      case ap::Job::State::kCancelled:
        follow_path_.setPreempted(result, result.message);
        return false;
      case ap::Job::State::kFailed:
        // The protocol has no host watchdog: the controller holds the last setpoint it received.
        result.message = "command link lost after " + std::to_string(job.sent()) + " setpoints: " + job.message() +
                         "; the controller holds the last setpoint it received, the node reconnects (send the "
                         "rest as a new goal)";
        ROS_WARN_STREAM("at_controller_node: follow_path: " << result.message);
        follow_path_.setAborted(result, result.message);
        return false;
      default:
        ROS_WARN_STREAM("at_controller_node: follow_path: " << result.message);
        follow_path_.setAborted(result, result.message);
        return false;
    }
  }

  /// state while an operation streams: DNC, its program, coolant, tool and spindle.
  void showStarted(const AtFollowPathGoal& goal, const ap::Operation& operation)
  {
    state_->update(
        [&](MachineState& s)
        {
          s.execution = MachineState::EXECUTION_ACTIVE;
          s.mode = MachineState::MODE_DNC;
          s.coolant = operation.coolant ? MachineState::COOLANT_ON : MachineState::COOLANT_OFF;
          s.program = goal.gcode_file.empty() ? "nav_msgs/Path" : goal.gcode_file;
          if (operation.tool)
          {
            s.tool = operation.tool->tool;
          }
          if (operation.spindle)
          {
            s.spindle_speed = *operation.spindle * session_->options().spindle_max_rpm / ap::kMaxFeed;
          }
        });
  }

  /// Carries out the program's stop, optional stop or dwell between two operations.
  /// \returns false if the goal was cancelled meanwhile.
  bool carryOut(const gcode::ProgramStep& step, AtFollowPathFeedback& feedback)
  {
    using Kind = gcode::ProgramStep::Kind;
    feedback.event = step.describe();
    feedback.paused = false;
    if (step.kind == Kind::kDwell)
    {
      state_->update([&](MachineState& s) { s.message = step.describe(); });
      follow_path_.publishFeedback(feedback);
      return waitWhileRunning(std::chrono::duration<double>(step.dwell_s), false);
    }
    // Read at each M01, as an operator flips the control's OPT STOP switch during a job.
    if (step.kind == Kind::kOptionalStop && !pnh_.param("optional_stop", true))
    {
      feedback.event += " passed (" + pnh_.resolveName("optional_stop") + " false)";
      follow_path_.publishFeedback(feedback);
      return true;
    }
    state_->update([&](MachineState& s) { s.block = step.line; });
    return holdUntilResume(step.describe(), step.describe(), feedback);
  }

  /// Holds the goal (nothing is sent) until ~resume: state PAUSED, feedback paused with
  /// "<event>: waiting for ~resume". \p hold completes "resumed after ..." in resume's answer.
  /// \returns false if the goal was cancelled meanwhile.
  bool holdUntilResume(const std::string& hold, const std::string& event, AtFollowPathFeedback& feedback)
  {
    feedback.event = event + ": waiting for " + pnh_.resolveName("resume");
    feedback.paused = true;
    feedback.stopping = false;
    {
      std::lock_guard<std::mutex> lock(hold_mutex_);
      hold_ = hold;
      resume_requested_ = false;
    }
    state_->update(
        [&](MachineState& s)
        {
          s.execution = MachineState::EXECUTION_PAUSED;
          s.message = feedback.event;
        });
    ROS_INFO_STREAM("at_controller_node: follow_path: " << feedback.event);
    follow_path_.publishFeedback(feedback);
    const bool resumed = waitWhileRunning(std::chrono::hours(24 * 365), true);
    {
      std::lock_guard<std::mutex> lock(hold_mutex_);
      hold_.clear();
    }
    feedback.paused = false;
    return resumed;
  }

  /// Waits for \p time, or (\p until_resume) for ~resume; false if the goal is cancelled first.
  bool waitWhileRunning(std::chrono::duration<double> time, bool until_resume)
  {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration_cast<Milliseconds>(time);
    std::unique_lock<std::mutex> lock(hold_mutex_);
    for (;;)
    {
      if (until_resume && resume_requested_)
      {
        return true;
      }
      if (std::chrono::steady_clock::now() >= deadline)
      {
        return !until_resume;
      }
      lock.unlock();
      if (follow_path_.isPreemptRequested() || !ros::ok() || stopping_)
      {
        return false;
      }
      lock.lock();
      // A cancel comes without a notification here: look again at least every 20 ms.
      hold_cv_.wait_until(lock, std::min(deadline, std::chrono::steady_clock::now() + Milliseconds(20)));
    }
  }

  /// ~resume: a goal held at the program's M00/M01, or paused because motion was disabled, goes
  /// on, if motion may start (enabled, e-stop released).
  bool resume(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    std::lock_guard<std::mutex> lock(hold_mutex_);
    if (hold_.empty())
    {
      res.success = false;
      res.message =
          "nothing to resume: no follow_path goal is held (at a program stop M00/M01, or paused by "
          "motion disabled)";
      return true;
    }
    res.message = session_->motionRefusal("resume");
    if (!res.message.empty())
    {
      return true;
    }
    resume_requested_ = true;
    res.success = true;
    res.message = "resumed after the " + hold_;
    hold_cv_.notify_all();
    return true;
  }

  void publishFeedback(const ap::Job& job, bool stopping, AtFollowPathFeedback& feedback)
  {
    feedback.setpoint = job.sent();
    feedback.setpoints_total = job.total();
    feedback.progress =
        feedback.setpoints_total > 0 ? static_cast<float>(feedback.setpoint) / feedback.setpoints_total : 0.0f;
    feedback.commanded = toPoint(job.current().position);
    feedback.reported = toPoint(session_->snapshot().position);
    feedback.following_error.x = feedback.commanded.x - feedback.reported.x;
    feedback.following_error.y = feedback.commanded.y - feedback.reported.y;
    feedback.following_error.z = feedback.commanded.z - feedback.reported.z;
    feedback.stopping = stopping;
    if (feedback.setpoint > 0)
    {
      follow_path_.publishFeedback(feedback);
    }
  }

  // ---- diagnostics --------------------------------------------------------------------------------

  void streamingDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
  {
    const auto stats = session_->sender().stats();
    const auto sequencer = session_->sender().sequencer();
    const ap::ControllerSnapshot now = session_->snapshot();
    if (now.estop == ap::EStop::kOn)
    {
      status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "emergency stop (E1)");
    }
    else if (now.estop != ap::EStop::kOff)
    {
      status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "emergency stop state unknown (no E0/E1 report yet)");
    }
    else if (stats.underruns > underruns_seen_)
    {
      status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "setpoint underruns since the last update");
    }
    else
    {
      status.summary(diagnostic_msgs::DiagnosticStatus::OK, std::string("phase: ") + ap::toString(sequencer.phase()));
    }
    underruns_seen_ = stats.underruns;
    status.add("setpoints sent", stats.setpoints);
    status.add("underruns (setpoint later than one period)", stats.underruns);
    status.add("stalls (schedule fell more than one period behind)", stats.stalls);
    status.add("latency mean (ms)", stats.mean_lateness * 1e3);
    status.add("latency max (ms)", stats.max_lateness * 1e3);
    status.add("interval p50 (ms)", stats.interval_p50 * 1e3);
    status.add("interval p99 (ms)", stats.interval_p99 * 1e3);
    status.add("interval max (ms)", stats.interval_max * 1e3);
    status.add("commands sent", stats.commands);
    status.add("command link reconnects", session_->commandReconnects());
    status.add("report link reconnects", session_->reportReconnects());
    status.add("report errors", session_->reportErrors());
    motion_->addTo(status);
    status.add("mode", now.jog_axis >= 0 ? std::string("jog ") + "XYZ"[now.jog_axis] : std::string("auto or unknown"));
    status.add("at home", now.at_home);
    status.add("jog deadman (s, 0: off)", std::chrono::duration<double>(session_->jogDeadman().timeout()).count());
    {
      std::lock_guard<std::mutex> lock(jog_stop_mutex_);
      status.add("last jog stop", last_jog_stop_.empty() ? std::string("none") : last_jog_stop_);
    }
    status.add("spindle value (0..255)", sequencer.spindle());
    status.add("report mode", report_mode_);
  }

  ros::NodeHandle pnh_;
  std::string report_mode_;
  std::unique_ptr<RuntimeSwitch> motion_;
  std::unique_ptr<ToMachineFrame> to_machine_;  // path goals in other frames
  std::atomic<bool> stopping_{false};
  std::mutex hold_mutex_;            // guards hold_, resume_requested_
  std::condition_variable hold_cv_;  // ~resume
  std::string hold_;                 // what a held goal waits after, for ~resume's answer ("" when none)
  bool resume_requested_ = false;
  uint64_t underruns_seen_ = 0;
  ros::SteadyTimer jog_timer_;  // one-shot, fires when the jog deadman may expire
  std::mutex jog_stop_mutex_;   // guards last_jog_stop_
  std::string last_jog_stop_;   // the deadman's last stop, for diagnostics

  std::unique_ptr<MachineStatePublisher> state_;
  std::unique_ptr<ap::ControllerSession> session_;
  SingleGoalActionServer<AtFollowPathAction> follow_path_;
  ros::ServiceServer set_auto_srv_, jog_srv_, spindle_srv_, coolant_srv_, tool_srv_, home_srv_, resume_srv_;
  ros::Publisher path_pub_;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::AtControllerNode>(argc, argv, "at_controller_node");
}
