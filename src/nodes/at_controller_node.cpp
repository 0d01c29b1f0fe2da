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
#include <memory>

#include "cnc_bridge/AtFollowPathAction.h"
#include "cnc_bridge/AtJog.h"
#include "cnc_bridge/AtSpindle.h"
#include "cnc_bridge/AtToolChange.h"
#include "cnc_bridge/at_protocol/controller_session.h"
#include "cnc_bridge/at_protocol/goal_runner.h"
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
    goal_runner_ = std::make_unique<ap::GoalRunner>(
        *session_, ap::GoalRunner::Names{pnh.resolveName("resume"), pnh.resolveName("set_motion_enabled"),
                                         pnh.resolveName("optional_stop")});

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
    goal_runner_->wake();
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

  /// The goal's operations run by the goal runner: a refusal, a plan that fails or its outcome.
  ap::GoalOutcome runGoal(const AtFollowPathGoal& goal)
  {
    ap::GoalOutcome refused;
    refused.end = ap::GoalOutcome::End::kAborted;
    refused.message = session_->motionRefusal("follow_path");
    if (!refused.message.empty())
    {
      return refused;
    }
    const ap::ControllerSnapshot now = session_->snapshot();
    if (!now.position_valid)
    {
      refused.message = "the controller has not reported its position yet (is the report link up?)";
      return refused;
    }
    try
    {
      // ~program_commands is read at each goal.
      const std::vector<Plan> plans = session_->planGoal(
          goalRequest(goal), now.position, pnh_.param("program_commands", false), pnh_.resolveName("program_commands"));
      publishPlannedPath(plans);  // before motion: the path is known once the goal is accepted
      GoalView view(*this, goal);
      return goal_runner_->run(plans, goal.tool, goal.tool_length, view);
    }
    catch (const std::exception& e)
    {
      refused.message = e.what();
      return refused;
    }
  }

  void followPath(const AtFollowPathGoalConstPtr& goal)
  {
    const ap::GoalOutcome outcome = runGoal(*goal);
    AtFollowPathResult result;
    result.success = outcome.end == ap::GoalOutcome::End::kSucceeded;
    result.message = outcome.message;
    result.setpoints = outcome.setpoints;
    result.underruns = static_cast<uint32_t>(outcome.underruns);
    if (outcome.final_position)
    {
      result.final_position = toPoint(*outcome.final_position);
    }
    switch (outcome.end)
    {
      case ap::GoalOutcome::End::kSucceeded:
        if (outcome.program_end)
        {
          state_->update([&](MachineState& s) { s.message = "follow_path: " + outcome.message; });
        }
        return follow_path_.setSucceeded(result, result.message);
      case ap::GoalOutcome::End::kCancelled:
        if (outcome.held_when_cancelled)
        {
          // Cancelled while nothing moved: nothing more was sent.
          state_->update(
              [&](MachineState& s)
              {
                s.execution = MachineState::EXECUTION_STOPPED;
                s.message = result.message;
              });
        }
        return follow_path_.setPreempted(result, result.message);
      case ap::GoalOutcome::End::kAborted:
        ROS_WARN_STREAM("at_controller_node: follow_path: " << result.message);
        return follow_path_.setAborted(result, result.message);
    }
  }

  /// One goal as the goal runner reports it: its feedback, and the machine's state.
  class GoalView : public ap::GoalListener
  {
   public:
    GoalView(AtControllerNode& node, const AtFollowPathGoal& goal) : node_(node), goal_(goal) {}

    bool cancelRequested() override { return node_.follow_path_.isPreemptRequested() || !ros::ok() || node_.stopping_; }
    // Read at each M01, as an operator flips the control's OPT STOP switch during a job.
    bool optionalStop() override { return node_.pnh_.param("optional_stop", true); }
    void operationStarted(const ap::Operation& operation) override { node_.showStarted(goal_, operation); }
    void operationProgress(const ap::Job& job, bool stopping, const ap::GoalFeedback& feedback) override
    {
      feedback_.setpoint = job.sent();
      feedback_.setpoints_total = job.total();
      feedback_.progress = job.total() > 0 ? static_cast<float>(job.sent()) / job.total() : 0.0f;
      feedback_.commanded = toPoint(job.current().position);
      feedback_.reported = toPoint(node_.session_->snapshot().position);
      feedback_.following_error.x = feedback_.commanded.x - feedback_.reported.x;
      feedback_.following_error.y = feedback_.commanded.y - feedback_.reported.y;
      feedback_.following_error.z = feedback_.commanded.z - feedback_.reported.z;
      feedback_.stopping = stopping;
      if (feedback_.setpoint > 0)
      {
        publish(feedback);
      }
    }
    void operationEnded(const ap::OperationResult& result) override { node_.showEnded(*result.job); }
    void dwelling(const ap::GoalFeedback& feedback) override
    {
      node_.state_->update([&](MachineState& s) { s.message = feedback.event; });
      publish(feedback);
    }
    void optionalStopPassed(const ap::GoalFeedback& feedback) override { publish(feedback); }
    void holding(const ap::GoalFeedback& feedback, uint32_t line) override
    {
      node_.state_->update(
          [&](MachineState& s)
          {
            s.block = line > 0 ? line : s.block;  // a program stop's line
            s.execution = MachineState::EXECUTION_PAUSED;
            s.message = feedback.event;
          });
      ROS_INFO_STREAM("at_controller_node: follow_path: " << feedback.event);
      feedback_.stopping = false;
      publish(feedback);
    }

   private:
    void publish(const ap::GoalFeedback& feedback)
    {
      feedback_.event = feedback.event;
      feedback_.paused = feedback.paused;
      node_.follow_path_.publishFeedback(feedback_);
    }

    AtControllerNode& node_;
    const AtFollowPathGoal& goal_;
    AtFollowPathFeedback feedback_;
  };

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

  /// state after an operation: READY, STOPPED (cancel, disable, failure) or ALARM (e-stop).
  void showEnded(const ap::Job& job)
  {
    const ap::ControllerSnapshot now = session_->snapshot();
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
  }

  /// ~resume: a goal held at the program's M00/M01, or paused because motion was disabled, goes
  /// on, if motion may start (enabled, e-stop released).
  bool resume(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    return answer(goal_runner_->resume(), res);
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
  uint64_t underruns_seen_ = 0;
  ros::SteadyTimer jog_timer_;  // one-shot, fires when the jog deadman may expire
  std::mutex jog_stop_mutex_;   // guards last_jog_stop_
  std::string last_jog_stop_;   // the deadman's last stop, for diagnostics

  std::unique_ptr<MachineStatePublisher> state_;
  std::unique_ptr<ap::ControllerSession> session_;
  std::unique_ptr<ap::GoalRunner> goal_runner_;
  SingleGoalActionServer<AtFollowPathAction> follow_path_;
  ros::ServiceServer set_auto_srv_, jog_srv_, spindle_srv_, coolant_srv_, tool_srv_, home_srv_, resume_srv_;
  ros::Publisher path_pub_;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::AtControllerNode>(argc, argv, "at_controller_node");
}
