// at_controller_node: ROS in the place of the CAM add-in of docs/protocols/at_protocol.md,
// driving a real-time controller over the '@'-protocol. Commands go out on one TCP socket (we are
// the client of the controller's receive server); reports come back on another (we are its client,
// or a server it connects to). Services change mode, spindle, tool and home; the ~follow_path action
// plans a G-code program or a nav_msgs/Path into 1 ms setpoints that a dedicated sender thread
// streams; reports become state, joint_states and tf.
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>

#include <cmath>
#include <condition_variable>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>

#include "cnc_bridge/AtFollowPathAction.h"
#include "cnc_bridge/AtJog.h"
#include "cnc_bridge/AtSpindle.h"
#include "cnc_bridge/AtToolChange.h"
#include "cnc_bridge/at_protocol/codec.h"
#include "cnc_bridge/at_protocol/deadman.h"
#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/at_protocol/program_path.h"
#include "cnc_bridge/at_protocol/sender.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/gcode/gcode.h"
#include "cnc_bridge/gcode/program_steps.h"
#include "cnc_bridge/ros/gcode_params.h"
#include "cnc_bridge/ros/machine_frame.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/ros/single_goal_action_server.h"
#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/tcp.h"

namespace cnc_bridge
{
namespace ap = at_protocol;

class AtControllerNode
{
 public:
  AtControllerNode(ros::NodeHandle nh, ros::NodeHandle pnh)
      : nh_(nh),
        pnh_(pnh),
        follow_path_(
            pnh, "follow_path", [this](const AtFollowPathGoalConstPtr& goal) { followPath(goal); },
            [](const AtFollowPathGoal& goal)
            {
              return goal.gcode_file.empty() ? "path of " + std::to_string(goal.path.poses.size()) + " poses"
                                             : "program " + goal.gcode_file;
            })
  {
    // ~host: address of the controller (both sockets in client mode).
    pnh.param<std::string>("host", host_, "127.0.0.1");
    // ~tcp_port: the controller's command server (the paper's server_recv).
    command_port_ = params::tcpPort(pnh, "tcp_port", 5000);
    // ~report_mode: "client" connects to the controller's report server (the paper's server_send,
    // like the add-in's ReceiveClient); "server" listens on ~listen_port for the controller.
    report_mode_ = params::choice(pnh, "report_mode", "client", {"client", "server"});
    // ~report_port: the controller's report server (client mode).
    report_port_ = params::tcpPort(pnh, "report_port", 5001);
    // ~listen_port: our report server (server mode); 0 picks a free port (logged).
    listen_port_ = params::tcpPort(pnh, "listen_port", 5001, params::PortZero::kMeansAny);
    // ~connect_timeout: s allowed for one TCP connect.
    connect_timeout_ = params::seconds(pnh, "connect_timeout", 2.0);
    // ~program_dir: directory G-code goals are read from; empty refuses G-code goals.
    std::string program_dir;
    pnh.param<std::string>("program_dir", program_dir, "");
    if (!program_dir.empty())
    {
      program_dir_ = std::make_unique<ProgramDirectory>(program_dir);
    }
    // ~period: s, the controller's time loop (1 ms in the paper).
    limits_.period = params::positive(pnh, "period", 0.001);
    // ~max_speed_x/y/z: m/s per axis; also the speed a feed value of 255 stands for.
    // ~max_accel_x/y/z: m/s^2 per axis.
    const char* axes[] = {"x", "y", "z"};
    const double default_speed[] = {0.05, 0.05, 0.025}, default_accel[] = {0.5, 0.5, 0.25};
    for (int i = 0; i < 3; ++i)
    {
      // The planner works in mm (the machinist's unit): m * 1000.
      limits_.max_speed[i] = params::positive(pnh, std::string("max_speed_") + axes[i], default_speed[i]) * 1000.0;
      limits_.max_accel[i] = params::positive(pnh, std::string("max_accel_") + axes[i], default_accel[i]) * 1000.0;
    }
    // ~corner_share: share of the acceleration kept for changes of direction at corners (0..1).
    pnh.param("corner_share", limits_.corner_share, 0.2);
    // ~profile: trapezoid (acceleration jumps) or scurve (jerk-limited, ~max_jerk_x/y/z in m/s^3).
    std::string profile;
    pnh.param<std::string>("profile", profile, "trapezoid");
    if (profile != "trapezoid" && profile != "scurve")
    {
      throw ConfigError(pnh.resolveName("profile") + " must be trapezoid or scurve, not '" + profile + "'");
    }
    limits_.profile = profile == "scurve" ? ap::Profile::kSCurve : ap::Profile::kTrapezoid;
    const double default_jerk[] = {10.0, 10.0, 5.0};
    for (int i = 0; i < 3; ++i)
    {
      limits_.max_jerk[i] = params::positive(pnh, std::string("max_jerk_") + axes[i], default_jerk[i]) * 1000.0;
    }
    limits_.validate();
    // ~transform_timeout: s a path goal in another frame waits for its transform into the machine frame.
    to_machine_ = std::make_unique<ToMachineFrame>(params::positive(pnh, "transform_timeout", 0.5));
    // ~default_feed_rate: m/s along the path when neither the goal nor the program gives one.
    default_feed_ = params::positive(pnh, "default_feed_rate", 0.01);
    // ~gcode_dialect (string, "haas"): haas, fanuc or linuxcnc, where the controls read G-code
    // differently (docs/gcode.md); ~tool_table (string, ""): tool diameters for G41/G42.
    params::gcodeOptions(pnh, gcode_options_);
    // ~spindle_max_rpm: rev/min that the spindle value 255 stands for.
    spindle_max_rpm_ = params::positive(pnh, "spindle_max_rpm", 24000.0);
    // ~coolant: whether operations use coolant (P1@) unless a goal says otherwise; ~coolant service.
    coolant_ = pnh.param("coolant", false);
    // ~realtime_priority: SCHED_FIFO priority of the 1 ms sender thread (with locked memory), 50 by
    // default: the priority of the kernel's threaded interrupt handlers on PREEMPT_RT, so no
    // ordinary thread delays a setpoint while device interrupts still come first. 0 keeps the
    // normal scheduler; where real time is not permitted the sender falls back to it with one
    // warning naming what allows it.
    int priority = 50;
    pnh.param("realtime_priority", priority, 50);
    // ~jog_timeout: s a jog moves after its last ~jog call (the deadman, as teleoperation commands
    // have one); a client renews it by calling ~jog again. 0 turns the deadman off.
    const double jog_timeout = pnh.param("jog_timeout", 0.5);
    if (!(jog_timeout >= 0.0))
    {
      throw ConfigError(pnh.resolveName("jog_timeout") + " must be 0 (no deadman) or a positive number of seconds");
    }
    jog_deadman_ = std::make_unique<ap::Deadman>(jog_timeout);
    if (!jog_deadman_->enabled())
    {
      ROS_WARN_STREAM("at_controller_node: " << pnh.resolveName("jog_timeout")
                                             << " is 0: the jog deadman is off, a jog goes on until the next jog, "
                                                "set_auto or a disable, even if its client has gone");
    }
    // One-shot, started by each jog; a steady clock, so a change of the system time cannot stop or delay it.
    jog_timer_ = nh.createSteadyTimer(ros::WallDuration(std::max(jog_timeout, 0.001)), &AtControllerNode::onJogTimer,
                                      this, true, false);

    const std::string hardware_id = host_ + ":" + std::to_string(command_port_);
    state_ = std::make_unique<MachineStatePublisher>(nh, pnh, hardware_id);
    // ~enable_motion (start-up value) and ~set_motion_enabled (at run time): nothing that moves
    // axes or turns the spindle is sent unless motion is enabled.
    motion_ = std::make_unique<RuntimeSwitch>(pnh, "motion", "enable_motion", "set_motion_enabled",
                                              [this](bool enabled, const std::string& caller)
                                              { onMotionSwitched(enabled, caller); });
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

    ap::SetpointSender::Options options;
    options.period = limits_.period;
    options.realtime_priority = priority;
    options.write_timeout = params::seconds(pnh, "write_timeout", 0.2);
    options.on_link_error = [this](const std::string& why) { commandLinkFailed(why); };
    sender_ = std::make_unique<ap::SetpointSender>(options);

    if (report_mode_ == "server")
    {
      report_server_ = std::make_unique<TcpServer>(listen_port_);
      ROS_INFO_STREAM("at_controller_node: waiting for the controller's reports on " << report_server_->describe());
    }
    startLinks();

    set_auto_srv_ = pnh.advertiseService("set_auto", &AtControllerNode::setAuto, this);
    jog_srv_ = pnh.advertiseService("jog", &AtControllerNode::jog, this);
    spindle_srv_ = pnh.advertiseService("spindle", &AtControllerNode::spindle, this);
    coolant_srv_ = pnh.advertiseService("coolant", &AtControllerNode::coolant, this);
    tool_srv_ = pnh.advertiseService("tool_change", &AtControllerNode::toolChange, this);
    home_srv_ = pnh.advertiseService("home", &AtControllerNode::home, this);
    resume_srv_ = pnh.advertiseService("resume", &AtControllerNode::resume, this);
    follow_path_.start();
  }

  ~AtControllerNode()
  {
    stopping_ = true;
    // A goal in progress is cancelled (decelerates to a stop) and its thread joined while the
    // sender and the links it uses still exist.
    follow_path_.shutdown();
    command_cv_.notify_all();
    if (report_server_)
    {
      report_server_->interrupt();
    }
    report_link_->stop();
    command_link_->stop();
    sender_.reset();
  }

 private:
  // ---- links ------------------------------------------------------------------------------------

  void startLinks()
  {
    Reconnector::Callbacks command;
    command.connect = [this]
    {
      auto link = std::shared_ptr<TcpConnection>(TcpConnection::connect(host_, command_port_, connect_timeout_));
      {
        std::lock_guard<std::mutex> lock(command_mutex_);
        command_failed_ = false;
        command_conn_ = link;
      }
      sender_->setLink(link);
    };
    command.session = [this]
    {
      std::unique_lock<std::mutex> lock(command_mutex_);
      command_cv_.wait(lock, [this] { return command_failed_ || stopping_; });
      if (command_failed_ && !stopping_)
      {
        throw LinkError(command_error_);
      }
    };
    command.disconnect = [this]
    {
      sender_->setLink(nullptr);
      std::shared_ptr<TcpConnection> link;
      {
        std::lock_guard<std::mutex> lock(command_mutex_);
        link.swap(command_conn_);
        command_failed_ = true;
      }
      command_cv_.notify_all();
      if (link)
      {
        link->interrupt();  // the sender may still hold it for one write
      }
    };
    command.on_state = [this](LinkState state, const std::string& why) { linkChanged(0, state, why); };
    command_link_ = std::make_unique<Reconnector>(
        "at_controller command link " + host_ + ":" + std::to_string(command_port_), command);

    Reconnector::Callbacks report;
    report.connect = [this]
    {
      std::shared_ptr<TcpConnection> link;
      if (report_server_)
      {
        while (!link && !stopping_)
        {
          link = report_server_->accept(Milliseconds(500));
        }
        if (!link)
        {
          throw CancelledError("stopping");
        }
      }
      else
      {
        link = TcpConnection::connect(host_, report_port_, connect_timeout_);
      }
      std::lock_guard<std::mutex> lock(report_mutex_);
      report_conn_ = link;
    };
    report.session = [this] { readReports(); };
    report.disconnect = [this]
    {
      std::lock_guard<std::mutex> lock(report_mutex_);
      if (report_conn_)
      {
        report_conn_->interrupt();
      }
    };
    report.on_state = [this](LinkState state, const std::string& why) { linkChanged(1, state, why); };
    const std::string where = report_server_ ? report_server_->describe() : host_ + ":" + std::to_string(report_port_);
    report_link_ = std::make_unique<Reconnector>("at_controller report link " + where, report);
    command_link_->start();
    report_link_->start();
  }

  void commandLinkFailed(const std::string& why)
  {
    {
      std::lock_guard<std::mutex> lock(command_mutex_);
      command_failed_ = true;
      command_error_ = why;
    }
    command_cv_.notify_all();
  }

  /// \param which 0: command link, 1: report link. The state's link is the worse of the two.
  void linkChanged(int which, LinkState state, const std::string& why)
  {
    // The two links' threads report at once when both come up; published out of order, a stale
    // CONNECTING could land after UP and stay: one change at a time, published in order.
    std::lock_guard<std::mutex> order(link_change_mutex_);
    LinkState combined;
    {
      std::lock_guard<std::mutex> lock(report_mutex_);
      links_[which] = state;
      combined = links_[0] == LinkState::kUp && links_[1] == LinkState::kUp       ? LinkState::kUp
                 : links_[0] == LinkState::kDown || links_[1] == LinkState::kDown ? LinkState::kDown
                                                                                  : LinkState::kConnecting;
    }
    state_->setLink(combined, why.empty() ? "" : (which == 0 ? "command link: " : "report link: ") + why);
    if (which == 1 && state != LinkState::kUp)
    {
      // Without reports the e-stop is not known any more: motion waits for the next E0.
      estop_ = MachineState::ESTOP_UNKNOWN;
      state_->update([](MachineState& s) { s.estop = MachineState::ESTOP_UNKNOWN; });
    }
  }

  void readReports()
  {
    std::shared_ptr<TcpConnection> link;
    {
      std::lock_guard<std::mutex> lock(report_mutex_);
      link = report_conn_;
    }
    ap::LineReassembler lines;
    uint8_t buffer[4096];
    while (!stopping_)
    {
      const size_t n = link->read(buffer, sizeof(buffer), Milliseconds(500));
      if (n == 0)
      {
        continue;
      }
      const auto result = lines.feed(buffer, n);
      for (const auto& error : result.errors)
      {
        ++report_errors_;
        ROS_WARN_STREAM_THROTTLE(5.0, "at_controller_node: " << error);
      }
      for (const auto& line : result.messages)
      {
        try
        {
          onReport(ap::parseReport(line));
        }
        catch (const ProtocolError& e)
        {
          ++report_errors_;
          ROS_WARN_STREAM_THROTTLE(5.0, "at_controller_node: " << e.what());
        }
      }
    }
  }

  void onReport(const ap::Report& report)
  {
    if (const auto* estop = std::get_if<ap::EStopReport>(&report))
    {
      estop_ = estop->active ? MachineState::ESTOP_ON : MachineState::ESTOP_OFF;
      if (estop->active)
      {
        sender_->abortRunning("emergency stop reported by the controller (E1)");
      }
      state_->update(
          [&](MachineState& s)
          {
            s.estop = estop->active ? MachineState::ESTOP_ON : MachineState::ESTOP_OFF;
            s.execution = estop->active ? MachineState::EXECUTION_ALARM : MachineState::EXECUTION_READY;
            s.message = estop->active ? "emergency stop (E1)" : "emergency stop released (E0)";
          });
    }
    else if (std::holds_alternative<ap::AutoModeReport>(report))
    {
      jog_axis_ = -1;
      jog_deadman_->disarm();  // the controller left jog mode (its mode selector)
      state_->update(
          [&](MachineState& s)
          {
            s.mode = MachineState::MODE_AUTO;
            s.message = "auto mode";
          });
    }
    else if (const auto* jog = std::get_if<ap::JogModeReport>(&report))
    {
      jog_axis_ = static_cast<int>(jog->axis);
      state_->update(
          [&](MachineState& s)
          {
            s.mode = MachineState::MODE_MANUAL;
            s.message = std::string("jog mode, axis ") + ap::toChar(jog->axis);
          });
    }
    else if (const auto* position = std::get_if<ap::PositionReport>(&report))
    {
      std::array<int32_t, 3> previous;
      {
        std::lock_guard<std::mutex> lock(report_mutex_);
        previous = reported_;
        reported_ = position->position;
        position_valid_ = true;
      }
      if (at_home_ && previous != position->position)
      {
        at_home_ = false;
      }
      // Pulses of 1/1000 mm to metres.
      state_->setPosition(position->position[0] / ap::kPulsesPerMetre, position->position[1] / ap::kPulsesPerMetre,
                          position->position[2] / ap::kPulsesPerMetre);
    }
    else if (std::holds_alternative<ap::HomeReport>(report))
    {
      at_home_ = true;
      state_->update([&](MachineState& s) { s.message = "at home"; });
    }
  }

  // ---- services ---------------------------------------------------------------------------------

  /// ~set_motion_enabled: disabling stops what moves (a running path decelerates along the path to
  /// a stop and holds, its goal paused until enabled and ~resume; a jog gets feed 0) and says so in
  /// state.
  void onMotionSwitched(bool enabled, const std::string& caller)
  {
    state_->update([&](MachineState& s)
                   { s.message = std::string("motion ") + (enabled ? "enabled" : "disabled") + " by " + caller; });
    if (enabled)
    {
      return;
    }
    {
      std::lock_guard<std::mutex> lock(job_mutex_);
      motion_disabled_by_ = caller;
      if (running_job_ && !running_job_->done())
      {
        disabled_by_ = caller;
        running_job_->cancel();
      }
    }
    jog_deadman_->disarm();  // the jog gets feed 0 here
    if (jog_axis_ >= 0)
    {
      try
      {
        sender_->send(ap::JogFeed{0});  // jog feed 0: the axis stops
      }
      catch (const Error& e)
      {
        ROS_WARN_STREAM("at_controller_node: jog stop on disable: " << e.what());
      }
    }
  }

  /// Refuses motion unless enabled and the e-stop is released. \returns the refusal or "".
  std::string motionRefusal(const std::string& what) const
  {
    if (!motion_->enabled())
    {
      return motion_->refusal(what);
    }
    if (estop_ == MachineState::ESTOP_ON)
    {
      return what + " refused: the controller reports an emergency stop (E1)";
    }
    if (estop_ != MachineState::ESTOP_OFF)
    {
      // Unknown is not clear: the controller has not said E0 on this report connection.
      return what +
             " refused: the controller's emergency stop state is unknown (no E0/E1 report on the report link "
             "yet); motion starts once it reports E0";
    }
    return "";
  }

  /// Queues the commands and waits until they are written. \returns false with the reason.
  bool sendAll(const std::vector<ap::Command>& commands, std::string& message)
  {
    try
    {
      std::vector<std::future<void>> written;
      for (const auto& command : commands)
      {
        written.push_back(sender_->send(command));
      }
      std::string sent;
      for (size_t i = 0; i < written.size(); ++i)
      {
        if (written[i].wait_for(std::chrono::seconds(2)) != std::future_status::ready)
        {
          message = "the command link did not take " + ap::describe(commands[i]) + " within 2 s";
          return false;
        }
        written[i].get();
        sent += ap::encode(commands[i]);
      }
      message = "sent " + sent;
      return true;
    }
    catch (const Error& e)
    {
      message = e.what();
      return false;
    }
  }

  bool setAuto(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    res.success = sendAll({ap::AutoMode{}}, res.message);
    if (res.success)
    {
      jog_deadman_->disarm();  // auto mode ends the jog
    }
    return true;
  }

  bool jog(AtJog::Request& req, AtJog::Response& res)
  {
    res.message = motionRefusal("jog");
    if (!res.message.empty())
    {
      return true;
    }
    try
    {
      if (req.axis.size() != 1)
      {
        throw ProtocolError("axis must be x, y or z, not \"" + req.axis + "\"");
      }
      const ap::Axis axis = ap::axisFromChar(req.axis[0]);
      // m/s to the F value: a fraction of the axis' top speed (mm/s), 0..255.
      const double mm_per_s = req.feed_rate * 1000.0;
      const long feed = std::lround(mm_per_s / limits_.max_speed[static_cast<int>(axis)] * ap::kMaxFeed);
      if (!(req.feed_rate >= 0.0) || feed > ap::kMaxFeed)
      {
        throw ProtocolError("jog feed_rate " + std::to_string(req.feed_rate) + " m/s is outside 0.." +
                            std::to_string(limits_.max_speed[static_cast<int>(axis)] / 1000.0) + " m/s (~max_speed_" +
                            static_cast<char>(std::tolower(ap::toChar(axis))) + ")");
      }
      res.success = sendAll({ap::JogMode{axis}, ap::JogFeed{static_cast<int>(feed)}}, res.message);
      if (res.success)
      {
        renewJogDeadman(feed > 0);
      }
    }
    catch (const Error& e)
    {
      res.message = e.what();
    }
    return true;
  }

  /// A jog command went out: a moving jog (re)arms the deadman for ~jog_timeout, feed 0 disarms it.
  void renewJogDeadman(bool moving)
  {
    if (!jog_deadman_->enabled())
    {
      return;
    }
    jog_timer_.stop();
    if (!moving)
    {
      jog_deadman_->disarm();
      return;
    }
    jog_deadman_->renew(ap::Deadman::Clock::now());
    jog_timer_.setPeriod(ros::WallDuration(std::chrono::duration<double>(jog_deadman_->timeout()).count()));
    jog_timer_.start();
  }

  /// The deadman's timer: a jog with no ~jog call for ~jog_timeout gets feed 0 (as a disable does).
  void onJogTimer(const ros::SteadyTimerEvent&)
  {
    ap::Deadman::Clock::duration remaining{};
    if (!jog_deadman_->expire(ap::Deadman::Clock::now(), &remaining))
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
    const std::string why = "jog stopped: " + jog_deadman_->describe("jog command");
    std::string sent;
    const bool stopped = sendAll({ap::JogFeed{0}}, sent);
    {
      std::lock_guard<std::mutex> lock(jog_stop_mutex_);
      last_jog_stop_ = stopped ? why : why + ", but feed 0 could not be sent: " + sent;
    }
    if (stopped)
    {
      ROS_WARN_STREAM("at_controller_node: " << why << " (" << pnh_.resolveName("jog_timeout") << "): sent F0@");
    }
    else
    {
      ROS_ERROR_STREAM("at_controller_node: " << why << ", but feed 0 could not be sent: " << sent);
    }
    state_->update([&](MachineState& s) { s.message = stopped ? why : why + " (feed 0 not sent: " + sent + ")"; });
  }

  bool spindle(AtSpindle::Request& req, AtSpindle::Response& res)
  {
    // rev/min to the S value 0..255 (clockwise only).
    const long value = std::lround(req.speed / spindle_max_rpm_ * ap::kMaxFeed);
    if (!(req.speed >= 0.0) || value > ap::kMaxFeed)
    {
      res.message = "spindle speed " + std::to_string(req.speed) + " rev/min is outside 0.." +
                    std::to_string(spindle_max_rpm_) + " (~spindle_max_rpm; clockwise only)";
      return true;
    }
    if (value > 0)  // stopping the spindle is always allowed
    {
      res.message = motionRefusal("spindle start");
      if (!res.message.empty())
      {
        return true;
      }
    }
    res.success = sendAll({ap::Spindle{static_cast<int>(value)}}, res.message);
    if (res.success)
    {
      state_->update([&](MachineState& s) { s.spindle_speed = value * spindle_max_rpm_ / ap::kMaxFeed; });
    }
    return true;
  }

  bool coolant(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res)
  {
    // The protocol switches coolant only with an operation (P1@ / P0@, steps 5-6 and 16).
    coolant_ = req.data;
    res.success = true;
    res.message = std::string("coolant ") + (req.data ? "on (P1@)" : "off (P0@)") +
                  " for the next operations; the protocol has no coolant command outside an operation";
    return true;
  }

  bool toolChange(AtToolChange::Request& req, AtToolChange::Response& res)
  {
    res.message = motionRefusal("tool change");
    if (!res.message.empty())
    {
      return true;
    }
    // The protocol sends the tool length in whole millimetres.
    const long length_mm = std::lround(req.length * 1000.0);
    res.success = sendAll({ap::ToolChange{req.tool, static_cast<int>(length_mm)}}, res.message);
    if (res.success)
    {
      state_->update([&](MachineState& s) { s.tool = req.tool; });
    }
    return true;
  }

  bool home(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    res.message = motionRefusal("go home");
    if (res.message.empty())
    {
      res.success = sendAll({ap::Home{}}, res.message);
    }
    return true;
  }

  // ---- follow_path --------------------------------------------------------------------------------

  using Plan = ap::OperationPlan;

  /// The goal as operations of points in pulses, the first starting at the reported position: one
  /// for a path; for a program, one per stretch of moves between the program's own steps (M00,
  /// M01, G04, M02/M30, and, with ~program_commands, spindle, coolant and tool changes, which
  /// the next operation's P@, T@ and S@ carry in the order of the protocol's steps).
  /// \throws Error with the reason.
  std::vector<Plan> planFromGoal(const AtFollowPathGoal& goal, const std::array<int32_t, 3>& start)
  {
    const ap::Vec3 start_pulses{double(start[0]), double(start[1]), double(start[2])};
    const bool coolant =
        goal.coolant == AtFollowPathGoal::COOLANT_ON || (goal.coolant == AtFollowPathGoal::COOLANT_DEFAULT && coolant_);
    std::vector<Plan> plans;
    const double goal_feed = goal.feed_rate * 1000.0;  // m/s to mm/s
    const double fallback_feed = goal_feed > 0.0 ? goal_feed : default_feed_ * 1000.0;
    const bool has_file = !goal.gcode_file.empty();
    if (has_file == !goal.path.poses.empty())
    {
      throw ConfigError("give exactly one of gcode_file and path");
    }
    if (has_file)
    {
      if (!program_dir_)
      {
        throw ConfigError("G-code goals need the parameter " + pnh_.resolveName("program_dir"));
      }
      const std::string file = program_dir_->resolveExisting(goal.gcode_file);
      std::ifstream in(file);
      if (!in)
      {
        throw ConfigError("cannot read " + file);
      }
      ap::ProgramPlanOptions options;
      options.goal_feed = goal_feed;
      options.fallback_feed = fallback_feed;
      options.coolant = coolant;
      options.program_commands = pnh_.param("program_commands", false);
      options.program_commands_setting = pnh_.resolveName("program_commands");
      plans = ap::planProgram(in, gcode_options_, options, start_pulses);
    }
    else
    {
      Plan& plan = plans.emplace_back();
      plan.points.push_back(start_pulses);
      plan.coolant = coolant;
      for (const auto& stamped : goal.path.poses)
      {
        // A pose names its frame, else the path's; empty means the machine frame.
        const std::string& frame =
            stamped.header.frame_id.empty() ? goal.path.header.frame_id : stamped.header.frame_id;
        const geometry_msgs::Pose pose =
            ToMachineFrame::apply(to_machine_->lookup(state_->frame("machine"), frame, "path"), stamped.pose);
        const auto& p = pose.position;
        // Metres to pulses, rounded so that the end point is a whole pulse.
        plan.points.push_back({std::round(p.x * ap::kPulsesPerMetre), std::round(p.y * ap::kPulsesPerMetre),
                               std::round(p.z * ap::kPulsesPerMetre)});
        plan.feeds.push_back(fallback_feed);
      }
    }
    for (Plan& each : plans)
    {
      ap::roundToPulses(each);
      if (goal.spindle_speed > 0.0)
      {
        each.spindle_rpm = goal.spindle_speed;
      }
      if (goal.coolant != AtFollowPathGoal::COOLANT_DEFAULT)
      {
        each.coolant = goal.coolant == AtFollowPathGoal::COOLANT_ON;
      }
    }
    if (goal.tool >= 0)
    {
      plans.front().tool = goal.tool;
    }
    return plans;
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

  static geometry_msgs::Point toPoint(const std::array<int32_t, 3>& pulses)
  {
    geometry_msgs::Point p;
    p.x = pulses[0] / ap::kPulsesPerMetre;
    p.y = pulses[1] / ap::kPulsesPerMetre;
    p.z = pulses[2] / ap::kPulsesPerMetre;
    return p;
  }

  std::array<int32_t, 3> reported(bool& valid)
  {
    std::lock_guard<std::mutex> lock(report_mutex_);
    valid = position_valid_;
    return reported_;
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
    std::string refusal = motionRefusal("follow_path");
    if (!refusal.empty())
    {
      return abort(refusal);
    }
    bool valid = false;
    const auto start = reported(valid);
    if (!valid)
    {
      return abort("the controller has not reported its position yet (is the report link up?)");
    }
    try
    {
      const std::vector<Plan> plans = planFromGoal(*goal, start);
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

  /// Where an operation stopped when motion was disabled: it decelerated along the path to rest.
  struct DisabledStop
  {
    std::string by;         ///< who disabled motion
    ap::Vec3 position{};    ///< pulses, the last setpoint (the controller holds it)
    double distance = 0.0;  ///< pulses along the operation's path
    uint64_t sent = 0;      ///< setpoints of the operation sent
    uint64_t planned = 0;   ///< setpoints the operation had
  };

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
      while (!motion_->enabled())
      {
        // Disabled between operations (during a dwell or a program stop): nothing is moving.
        std::string by;
        {
          std::lock_guard<std::mutex> lock(job_mutex_);
          by = motion_disabled_by_;
        }
        const std::string event =
            "motion disabled by " + by + " (" + pnh_.resolveName("set_motion_enabled") + ") before the next operation";
        if (!holdUntilResume("stop when motion was disabled by " + by, event, feedback))
        {
          endCancelled(result, "cancelled while held: " + event);
          return false;
        }
      }
      const std::string refusal = motionRefusal("follow_path");
      if (!refusal.empty())
      {
        // The e-stop (E1 or unknown) between operations: the goal cannot go on.
        result.message =
            refusal + (feedback.event.empty() ? "" : " (before the operation after " + feedback.event + ")");
        ROS_WARN_STREAM("at_controller_node: follow_path: " << result.message);
        follow_path_.setAborted(result, result.message);
        return false;
      }
      DisabledStop stop;
      if (runOperation(goal, rest, result, feedback, stop))
      {
        return true;
      }
      if (stop.by.empty())
      {
        return false;  // cancelled, e-stop or link failure: the goal has ended
      }
      std::ostringstream event;
      event << "motion disabled by " << stop.by << " (" << pnh_.resolveName("set_motion_enabled")
            << "): decelerated to a stop along the path at X" << stop.position[0] / ap::kPulsesPerMm << " Y"
            << stop.position[1] / ap::kPulsesPerMm << " Z" << stop.position[2] / ap::kPulsesPerMm << " mm after "
            << stop.sent << " of " << stop.planned << " planned setpoints";
      ROS_WARN_STREAM("at_controller_node: follow_path: " << event.str() << "; holding");
      if (!holdUntilResume("stop when motion was disabled by " + stop.by, event.str(), feedback))
      {
        endCancelled(result, "cancelled while held: " + event.str());
        return false;
      }
      const ap::PathRest left = ap::restOfPath(rest.points, rest.feeds, stop.distance, stop.position);
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
  /// either \p stop.by names who disabled motion (the operation decelerated to a stop and ended
  /// with #@ M0@; the goal goes on, paused) or the goal has been ended (cancelled, e-stop, link
  /// failure).
  bool runOperation(const AtFollowPathGoal& goal_msg, const Plan& plan, AtFollowPathResult& result,
                    AtFollowPathFeedback& feedback, DisabledStop& stop)
  {
    const AtFollowPathGoal* goal = &goal_msg;
    ap::Operation operation;
    operation.coolant = plan.coolant;
    if (plan.tool >= 0)
    {
      // The goal's tool length goes with its own tool; a program's tool change carries none.
      const double length = plan.tool == goal->tool ? goal->tool_length : 0.0;
      operation.tool = ap::ToolChange{plan.tool, static_cast<int>(std::lround(length * 1000.0))};
    }
    if (plan.spindle_rpm > 0.0)
    {
      const long value = std::lround(plan.spindle_rpm / spindle_max_rpm_ * ap::kMaxFeed);
      if (value > ap::kMaxFeed)
      {
        throw ConfigError("spindle speed " + std::to_string(plan.spindle_rpm) + " rev/min is above ~spindle_max_rpm");
      }
      operation.spindle = static_cast<int>(value);
    }
    operation.trajectory = std::make_shared<ap::Trajectory>(plan.points, plan.feeds, limits_);
    // The S-curve streams the trapezoid's steps plus its average's window less one.
    const size_t setpoints = ap::TrajectoryStream(*operation.trajectory).total();
    ROS_INFO_STREAM("at_controller_node: follow_path: "
                    << plan.points.size() - 1 << " segments, " << operation.trajectory->length() / ap::kPulsesPerMm
                    << " mm in " << setpoints * limits_.period << " s (" << setpoints << " setpoints)");
    const uint64_t underruns_before = sender_->stats().underruns;
    jog_deadman_->disarm();  // the controller leaves jog mode for machining
    const std::shared_ptr<ap::Job> job = sender_->start(operation);
    {
      std::lock_guard<std::mutex> lock(job_mutex_);
      running_job_ = job;
      disabled_by_.clear();
    }
    if (!motion_->enabled())
    {
      // Disabled between the check above and the start: stop at once.
      std::lock_guard<std::mutex> lock(job_mutex_);
      disabled_by_ = motion_disabled_by_;
      job->cancel();
    }
    state_->update(
        [&](MachineState& s)
        {
          s.execution = MachineState::EXECUTION_ACTIVE;
          s.mode = MachineState::MODE_DNC;
          s.coolant = operation.coolant ? MachineState::COOLANT_ON : MachineState::COOLANT_OFF;
          s.program = has(goal->gcode_file) ? goal->gcode_file : "nav_msgs/Path";
          if (operation.tool)
          {
            s.tool = operation.tool->tool;
          }
          if (operation.spindle)
          {
            s.spindle_speed = *operation.spindle * spindle_max_rpm_ / ap::kMaxFeed;
          }
        });
    feedback.paused = false;
    bool cancelled = false;
    while (!job->waitFor(Milliseconds(100)))
    {
      if (!cancelled && (follow_path_.isPreemptRequested() || !ros::ok() || stopping_))
      {
        job->cancel();
        cancelled = true;
      }
      publishFeedback(*job, cancelled, feedback);
    }
    publishFeedback(*job, cancelled, feedback);
    std::string disabled_by;
    {
      std::lock_guard<std::mutex> lock(job_mutex_);
      running_job_.reset();
      disabled_by.swap(disabled_by_);
    }
    result.setpoints += job->sent();
    result.underruns += static_cast<uint32_t>(sender_->stats().underruns - underruns_before);
    bool ignored;
    result.final_position = toPoint(reported(ignored));
    result.message = job->message();
    // A cancel of the goal wins over a disable that came at the same time.
    const bool stopped_by_disable = !disabled_by.empty() && !cancelled && job->state() == ap::Job::State::kCancelled;
    state_->update(
        [&](MachineState& s)
        {
          s.execution = estop_ == MachineState::ESTOP_ON             ? MachineState::EXECUTION_ALARM
                        : job->state() == ap::Job::State::kSucceeded ? MachineState::EXECUTION_READY
                                                                     : MachineState::EXECUTION_STOPPED;
          s.mode = jog_axis_ >= 0 ? MachineState::MODE_MANUAL : MachineState::MODE_AUTO;
          s.coolant = MachineState::COOLANT_OFF;  // #@ ends the operation's coolant
          s.spindle_speed = 0.0;                  // M0@ stops the spindle (step 18)
          s.message = "follow_path " + std::string(ap::Job::toString(job->state())) + ": " + job->message();
        });
    if (stopped_by_disable)
    {
      const ap::Setpoint last = job->current();
      stop.by = disabled_by;
      stop.position = {double(last.position[0]), double(last.position[1]), double(last.position[2])};
      stop.distance = job->distance();
      if (job->sent() == 0)
      {
        stop.position = plan.points.front();  // stopped before its first setpoint: still at the start
        stop.distance = 0.0;
      }
      stop.sent = job->sent();
      stop.planned = operation.trajectory->steps();
      return false;
    }
    switch (job->state())
    {
      case ap::Job::State::kSucceeded:
        return true;
      case ap::Job::State::kCancelled:
        follow_path_.setPreempted(result, result.message);
        return false;
      case ap::Job::State::kFailed:
        // The protocol has no host watchdog: the controller holds the last setpoint it received.
        result.message = "command link lost after " + std::to_string(job->sent()) + " setpoints: " + job->message() +
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
      std::lock_guard<std::mutex> lock(job_mutex_);
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
      std::lock_guard<std::mutex> lock(job_mutex_);
      hold_.clear();
    }
    feedback.paused = false;
    return resumed;
  }

  /// Waits for \p time, or (\p until_resume) for ~resume; false if the goal is cancelled first.
  bool waitWhileRunning(std::chrono::duration<double> time, bool until_resume)
  {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration_cast<Milliseconds>(time);
    std::unique_lock<std::mutex> lock(job_mutex_);
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
      job_cv_.wait_until(lock, std::min(deadline, std::chrono::steady_clock::now() + Milliseconds(20)));
    }
  }

  /// ~resume: a goal held at the program's M00/M01, or paused because motion was disabled, goes
  /// on, if motion may start (enabled, e-stop released).
  bool resume(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    if (hold_.empty())
    {
      res.success = false;
      res.message =
          "nothing to resume: no follow_path goal is held (at a program stop M00/M01, or paused by "
          "motion disabled)";
      return true;
    }
    res.message = motionRefusal("resume");
    if (!res.message.empty())
    {
      return true;
    }
    resume_requested_ = true;
    res.success = true;
    res.message = "resumed after the " + hold_;
    job_cv_.notify_all();
    return true;
  }

  static bool has(const std::string& text) { return !text.empty(); }

  void publishFeedback(const ap::Job& job, bool stopping, AtFollowPathFeedback& feedback)
  {
    feedback.setpoint = job.sent();
    feedback.setpoints_total = job.total();
    feedback.progress =
        feedback.setpoints_total > 0 ? static_cast<float>(feedback.setpoint) / feedback.setpoints_total : 0.0f;
    const ap::Setpoint current = job.current();
    bool valid;
    const auto reported_now = reported(valid);
    feedback.commanded = toPoint(current.position);
    feedback.reported = toPoint(reported_now);
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
    const auto stats = sender_->stats();
    const auto sequencer = sender_->sequencer();
    if (estop_ == MachineState::ESTOP_ON)
    {
      status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "emergency stop (E1)");
    }
    else if (estop_ != MachineState::ESTOP_OFF)
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
    status.add("command link reconnects", command_link_ ? command_link_->reconnects() : 0u);
    status.add("report link reconnects", report_link_ ? report_link_->reconnects() : 0u);
    status.add("report errors", report_errors_.load());
    motion_->addTo(status);
    status.add("mode", jog_axis_ >= 0 ? std::string("jog ") + "XYZ"[jog_axis_] : std::string("auto or unknown"));
    status.add("at home", at_home_.load());
    status.add("jog deadman (s, 0: off)", std::chrono::duration<double>(jog_deadman_->timeout()).count());
    {
      std::lock_guard<std::mutex> lock(jog_stop_mutex_);
      status.add("last jog stop", last_jog_stop_.empty() ? std::string("none") : last_jog_stop_);
    }
    status.add("spindle value (0..255)", sequencer.spindle());
    status.add("report mode", report_mode_);
  }

  ros::NodeHandle nh_, pnh_;
  std::string host_;
  uint16_t command_port_ = 0, report_port_ = 0, listen_port_ = 0;
  std::string report_mode_;
  Milliseconds connect_timeout_{2000};
  std::unique_ptr<RuntimeSwitch> motion_;
  std::unique_ptr<ToMachineFrame> to_machine_;  // path goals in other frames
  std::mutex job_mutex_;            // guards running_job_, disabled_by_, motion_disabled_by_, hold_, resume_requested_
  std::condition_variable job_cv_;  // ~resume
  std::string hold_;                // what a held goal waits after, for ~resume's answer ("" when none)
  bool resume_requested_ = false;
  std::shared_ptr<ap::Job> running_job_;
  std::string disabled_by_;         // who disabled motion while running_job_ ran
  std::string motion_disabled_by_;  // who disabled motion last
  std::unique_ptr<ProgramDirectory> program_dir_;
  ap::PlannerLimits limits_;
  double default_feed_ = 0.01;
  gcode::ParserOptions gcode_options_;
  double spindle_max_rpm_ = 24000.0;
  std::atomic<bool> coolant_{false};

  std::unique_ptr<MachineStatePublisher> state_;
  std::unique_ptr<ap::SetpointSender> sender_;
  std::unique_ptr<TcpServer> report_server_;
  std::unique_ptr<Reconnector> command_link_, report_link_;

  std::mutex command_mutex_;
  std::condition_variable command_cv_;
  std::shared_ptr<TcpConnection> command_conn_;
  bool command_failed_ = false;
  std::string command_error_;
  std::atomic<bool> stopping_{false};

  std::mutex report_mutex_;       // guards report_conn_, reported_, position_valid_, links_
  std::mutex link_change_mutex_;  // serialises linkChanged(): its state updates stay in order
  std::shared_ptr<TcpConnection> report_conn_;
  std::array<int32_t, 3> reported_{};
  bool position_valid_ = false;
  LinkState links_[2] = {LinkState::kDown, LinkState::kDown};

  std::atomic<uint8_t> estop_{MachineState::ESTOP_UNKNOWN};  ///< as last reported; unknown without a report link
  std::atomic<bool> at_home_{false};
  std::atomic<int> jog_axis_{-1};
  std::atomic<uint64_t> report_errors_{0};
  uint64_t underruns_seen_ = 0;

  std::unique_ptr<ap::Deadman> jog_deadman_;  // ~jog_timeout
  ros::SteadyTimer jog_timer_;                // one-shot, fires when the deadman may expire
  std::mutex jog_stop_mutex_;                 // guards last_jog_stop_
  std::string last_jog_stop_;                 // the deadman's last stop, for diagnostics

  SingleGoalActionServer<AtFollowPathAction> follow_path_;
  ros::ServiceServer set_auto_srv_, jog_srv_, spindle_srv_, coolant_srv_, tool_srv_, home_srv_, resume_srv_;
  ros::Publisher path_pub_;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::AtControllerNode>(argc, argv, "at_controller_node");
}
