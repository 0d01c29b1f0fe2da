// ethernut_node: drives an ethernut board (the qCNC opcode protocol over TCP) from ROS. It keeps
// the link up (init, mode, keepalive, reconnect), streams jobs from G-code files or point lists
// through the ~run_job action, carries pause/resume/reset/kill/mode requests, publishes the
// machine's reported and commanded position as state (the reported one as joint_states/tf), and a
// preview of each job for rviz before it runs. The protocol itself lives in the ROS-free
// cnc_bridge_ethernut library.
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <visualization_msgs/MarkerArray.h>

#include <atomic>
#include <cmath>
#include <condition_variable>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>

#include "cnc_bridge/EthernutSetMode.h"
#include "cnc_bridge/RunJobAction.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/ethernut/client.h"
#include "cnc_bridge/ethernut/settings.h"
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
namespace
{
// The board's unit is the millimetre (qCNC's coordinates are G-code values; our parser turns
// inches into mm); messages are in metres.
constexpr double kMetresPerMm = 0.001;

bool parseMode(const std::string& text, ethernut::BoardMode& mode)
{
  if (text == "file")
  {
    mode = ethernut::BoardMode::kFile;
  }
  else if (text == "gui-control")
  {
    mode = ethernut::BoardMode::kGuiControl;
  }
  else if (text == "standalone")
  {
    mode = ethernut::BoardMode::kStandalone;
  }
  else
  {
    return false;
  }
  return true;
}

// What to do with G53 moves (machine coordinates) in a G-code job. The board knows one coordinate
// system, the one the program's coordinates are streamed in; a G53 target in it would be a move
// to the wrong place (G53 Z0, a retract to the top of the machine, becomes a plunge to the work
// zero).
enum class G53Moves : uint8_t
{
  kRefuse,  ///< the job is refused before anything is sent
  kSkip     ///< left out of the stream and the preview; the next move keeps the unnamed axes
};

// The moves of a G-code program as the board gets them: G53 moves refused or left out.
class GcodeJob
{
 public:
  GcodeJob(const std::string& path, const gcode::ParserOptions& options, G53Moves g53, std::string g53_param)
      : in_(path, std::ios::binary),
        steps_(in_, withSeparateMachineMoves(options)),
        g53_(g53),
        g53_param_(std::move(g53_param))
  {
    if (!in_)
    {
      throw ConfigError("cannot open " + path);
    }
  }

  // The next move to stream; false at the end of the program, or at one of the program's own
  // steps (stop, end, dwell, spindle, coolant, tool change), which step() then holds: the stream
  // pauses there and the next call goes on after it. Throws ParseError, or ConfigError for a G53
  // move under kRefuse.
  bool next(gcode::Move& move)
  {
    step_.reset();
    gcode::ProgramStep step;
    while (steps_.next(step))
    {
      if (step.kind != gcode::ProgramStep::Kind::kMove)
      {
        step_ = step;
        return false;
      }
      move = step.move;
      if (!move.machine_coordinates)
      {
        return true;
      }
      if (g53_ == G53Moves::kRefuse)
      {
        throw ConfigError("G-code line " + std::to_string(move.line) +
                          ": G53 move to machine coordinates, which the board does not have (it knows one "
                          "coordinate system, the program's); set " +
                          g53_param_ + " to skip to leave G53 moves out");
      }
      if (skipped_lines_.size() < 5)
      {
        skipped_lines_.push_back(move.line);
      }
      ++skipped_;
    }
    return false;
  }

  // The program step next() stopped at, if it did not stop at the end of the program.
  const std::optional<gcode::ProgramStep>& step() const { return step_; }

  // "" when no G53 move was left out, else e.g. "3 G53 moves left out (lines 8, 58, 63)".
  std::string skippedSummary() const
  {
    if (skipped_ == 0)
    {
      return "";
    }
    std::string text = std::to_string(skipped_) + " G53 move" + (skipped_ == 1 ? "" : "s") + " left out (line";
    text += skipped_lines_.size() == 1 ? " " : "s ";
    for (size_t i = 0; i < skipped_lines_.size(); ++i)
    {
      text += (i ? ", " : "") + std::to_string(skipped_lines_[i]);
    }
    return text + (skipped_ > skipped_lines_.size() ? ", ...)" : ")");
  }

 private:
  static gcode::ParserOptions withSeparateMachineMoves(gcode::ParserOptions options)
  {
    options.separate_machine_moves = true;  // a skipped G53 move leaves the program position alone
    return options;
  }

  std::ifstream in_;
  gcode::ProgramSteps steps_;
  std::optional<gcode::ProgramStep> step_;
  G53Moves g53_;
  std::string g53_param_;
  uint64_t skipped_ = 0;
  std::vector<uint32_t> skipped_lines_;
};

uint8_t stateMode(ethernut::BoardMode mode)
{
  switch (mode)
  {
    case ethernut::BoardMode::kFile:
      return MachineState::MODE_DNC;  // the program is fed over the link while it runs
    case ethernut::BoardMode::kGuiControl:
      return MachineState::MODE_MANUAL;  // coordinates come from the host's controls
    case ethernut::BoardMode::kStandalone:
      return MachineState::MODE_AUTO;  // the board runs on its own
    default:
      return MachineState::MODE_UNKNOWN;
  }
}
}  // namespace

class EthernutNode : public ethernut::ClientListener
{
 public:
  EthernutNode(ros::NodeHandle nh, ros::NodeHandle pnh)
      : nh_(nh),
        pnh_(pnh),
        action_(
            pnh, "run_job", [this](const RunJobGoalConstPtr& goal) { execute(goal); },
            [](const RunJobGoal& goal)
            { return goal.file.empty() ? std::to_string(goal.points.size()) + " points" : "job " + goal.file; })
  {
    readParameters();
    state_ = std::make_unique<MachineStatePublisher>(nh_, pnh_, host_ + ":" + std::to_string(port_));
    state_->update(
        [&](MachineState& s)
        {
          s.mode = MachineState::MODE_UNKNOWN;
          s.execution = MachineState::EXECUTION_UNKNOWN;
          s.feed_rate = std::nan("");
          s.spindle_speed = std::nan("");
        });
    // ~enable_motion (bool, false) at start-up, ~set_motion_enabled at run time: ~run_job (and
    // ~resume, which lets a held move go on) only while motion is enabled; disabling it pauses a
    // running job (the board holds the move in progress).
    motion_ = std::make_unique<RuntimeSwitch>(pnh_, "motion", "enable_motion", "set_motion_enabled",
                                              [this](bool enabled, const std::string& caller)
                                              { onMotionSwitched(enabled, caller); });
    state_->diagnostics().add("ethernut protocol", this, &EthernutNode::protocolDiagnostics);
    path_pub_ = nh_.advertise<nav_msgs::Path>("job/path", 1, true);
    markers_pub_ = nh_.advertise<visualization_msgs::MarkerArray>("job/markers", 1, true);
    pause_srv_ = pnh_.advertiseService("pause", &EthernutNode::onPause, this);
    resume_srv_ = pnh_.advertiseService("resume", &EthernutNode::onResume, this);
    reset_srv_ = pnh_.advertiseService("reset", &EthernutNode::onReset, this);
    kill_srv_ = pnh_.advertiseService("kill", &EthernutNode::onKill, this);
    mode_srv_ = pnh_.advertiseService("set_mode", &EthernutNode::onSetMode, this);
    action_.start();

    Reconnector::Callbacks callbacks;
    callbacks.connect = [this] { connect(); };
    callbacks.session = [this] { runSession(); };
    callbacks.on_state = [this](LinkState link, const std::string& why) { state_->setLink(link, why); };
    callbacks.disconnect = [this] { disconnect(); };
    reconnector_ = std::make_unique<Reconnector>("ethernut " + host_ + ":" + std::to_string(port_), callbacks,
                                                 Backoff(Milliseconds(200), Milliseconds(5000)));
    reconnector_->start();
  }

  ~EthernutNode()
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    hold_cv_.notify_all();
    reconnector_->stop();
    action_.shutdown();
  }

 private:
  struct Session
  {
    std::shared_ptr<TcpConnection> link;  // declared first: destroyed after the client
    std::shared_ptr<ethernut::Client> client;
  };

  void readParameters()
  {
    // ~settings_file (string, ""): a qCNC settings file (TSS, NAME|value); its INET_ADD, INET_PORT,
    // INET_DEL and PROG_CNCkill are used where the ROS parameters below are left empty/zero.
    std::string settings_file;
    pnh_.param<std::string>("settings_file", settings_file, "");
    ethernut::Settings settings;
    if (!settings_file.empty())
    {
      settings = ethernut::readSettingsFile(settings_file);
    }
    // ~host (string, ""): the board's address; empty: INET_ADD of the settings file.
    pnh_.param<std::string>("host", host_, "");
    if (host_.empty())
    {
      if (!settings.address)
      {
        throw ConfigError("Required parameter " + pnh_.resolveName("host") +
                          " not given (nor INET_ADD in ~settings_file).");
      }
      host_ = *settings.address;
    }
    // ~tcp_port (int, 0): the board's TCP port; 0: INET_PORT of the settings file, else 6666.
    const uint16_t port = params::tcpPort(pnh_, "tcp_port", 0, params::PortZero::kMeansAny);
    port_ = port != 0 ? port : settings.port.value_or(6666);
    // ~dead_link_timeout (s, 0): silence after which the link is dead and is reconnected;
    // 0: INET_DEL (ms) of the settings file, else 2 s.
    double dead = 0.0;
    pnh_.param("dead_link_timeout", dead, 0.0);
    options_.dead_link_timeout =
        dead > 0 ? Milliseconds(static_cast<long>(dead * 1000)) : Milliseconds(settings.dead_link_ms.value_or(2000));
    // ~keepalive_period (s, 0.5): silence after which an alive request is sent.
    options_.keepalive_period = params::seconds(pnh_, "keepalive_period", 0.5);
    if (options_.dead_link_timeout <= options_.keepalive_period)
    {
      throw ConfigError(pnh_.resolveName("dead_link_timeout") + " must be longer than " +
                        pnh_.resolveName("keepalive_period"));
    }
    // ~rtt_probe_period (s, 5): an alive request also goes out when none did for this long, so the
    // link round trip is measured on a busy link too; 0: only when the board is silent.
    double probe = 5.0;
    pnh_.param("rtt_probe_period", probe, 5.0);
    if (probe < 0)
    {
      throw ConfigError(pnh_.resolveName("rtt_probe_period") + " must be >= 0");
    }
    options_.rtt_probe_period = Milliseconds(static_cast<long>(probe * 1000));
    // ~reply_timeout (s, 2): how long a command waits for the board's answer.
    options_.reply_timeout = params::seconds(pnh_, "reply_timeout", 2.0);
    // ~connect_timeout (s, 3): TCP connection timeout.
    connect_timeout_ = params::seconds(pnh_, "connect_timeout", 3.0);
    // ~max_resends (int, 5): RESENDs accepted for one set of coordinates before the job fails.
    int max_resends = 5;
    pnh_.param("max_resends", max_resends, 5);
    options_.max_resends = static_cast<unsigned>(std::max(0, max_resends));
    // ~enable_kill (bool, false) at start-up, ~set_kill_enabled at run time: allow ~kill (opcode
    // 99/99). PROG_CNCkill|1 in the settings file enables it too (qCNC enabled it by default; we
    // do not).
    kill_ = std::make_unique<RuntimeSwitch>(pnh_, "kill", "enable_kill", "set_kill_enabled");
    if (!kill_->enabled() && settings.kill_enabled.value_or(false))
    {
      kill_->set(true, "PROG_CNCkill|1 in " + settings_file);
    }
    // The client's own gate stays open: the node's switch decides, and it changes at run time
    // while one client serves a whole connection.
    options_.kill_enabled = true;
    // ~ack_position_reports (bool, true): answer the board's position reports with an ack (Table 1).
    pnh_.param("ack_position_reports", options_.ack_position_reports, true);
    // ~mode (string, "file"): board mode selected on every connection: file, gui-control, standalone.
    std::string mode;
    pnh_.param<std::string>("mode", mode, "file");
    if (!parseMode(mode, options_.initial_mode))
    {
      throw ConfigError(pnh_.resolveName("mode") + " must be file, gui-control or standalone, not '" + mode + "'");
    }
    // ~program_dir (string, ""): directory G-code jobs are read from; empty: only point jobs.
    std::string dir;
    pnh_.param<std::string>("program_dir", dir, "");
    if (!dir.empty())
    {
      program_dir_ = std::make_unique<ProgramDirectory>(dir);
    }
    // ~chord_tolerance (m, 0.00001): largest deviation of the streamed chords from a G02/G03 arc.
    parser_options_.chord_tolerance_mm = params::positive(pnh_, "chord_tolerance", 1e-5) / kMetresPerMm;
    // ~gcode_dialect (string, "haas"): haas, fanuc or linuxcnc, where the controls read G-code
    // differently (docs/gcode.md); ~tool_table (string, ""): tool diameters for G41/G42.
    params::gcodeOptions(pnh_, parser_options_);
    // ~g53_moves (string, "refuse"): G53 moves (machine coordinates) in G-code jobs, which the
    // board cannot carry out (it knows one coordinate system): refuse (the job is refused before
    // anything is sent) or skip (left out of the stream and the preview).
    const bool skip_g53 = params::choice(pnh_, "g53_moves", "refuse", {"refuse", "skip"}) == "skip";
    g53_moves_ = skip_g53 ? G53Moves::kSkip : G53Moves::kRefuse;
    // ~transform_timeout (s, 0.5): how long a points goal in another frame waits for its transform
    // into the machine frame.
    to_machine_ = std::make_unique<ToMachineFrame>(params::positive(pnh_, "transform_timeout", 0.5));
    // ~max_preview_points (int, 100000): job/path is thinned to at most this many poses.
    pnh_.param("max_preview_points", max_preview_points_, 100000);
    max_preview_points_ = std::max(max_preview_points_, 2);
  }

  // ------------------------------------------------------------------------- link
  void connect()
  {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      // Standalone mode: the board dropped us on purpose; wait for a request of another mode.
      hold_cv_.wait(lock, [&] { return !hold_ || stopping_; });
      if (stopping_)
      {
        throw CancelledError("stopping");
      }
    }
    ethernut::ClientOptions options;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      options = options_;
    }
    auto link = std::shared_ptr<TcpConnection>(TcpConnection::connect(host_, port_, connect_timeout_));
    auto client = std::make_shared<ethernut::Client>(*link, options, this);
    std::lock_guard<std::mutex> lock(mutex_);
    if (session_.client)
    {
      addCounts(earlier_sessions_, session_.client->stats());  // diagnostics count since the start
    }
    session_ = Session{link, client};
  }

  // Adds the counters of \p from to \p to (round-trip times are per connection).
  static void addCounts(ethernut::ClientStats& to, const ethernut::ClientStats& from)
  {
    to.coordinates_sent += from.coordinates_sent;
    to.coordinates_done += from.coordinates_done;
    to.resends += from.resends;
    to.keepalive_requests += from.keepalive_requests;
    to.keepalive_misses += from.keepalive_misses;
    to.bad_frames += from.bad_frames;
    to.unexpected_messages += from.unexpected_messages;
    to.alive_responses += from.alive_responses;
  }

  void runSession()
  {
    const Session s = session();
    s.client->run();
    if (s.client->state() == ethernut::SessionState::kStandalone)
    {
      std::lock_guard<std::mutex> lock(mutex_);
      hold_ = true;
    }
  }

  void disconnect()
  {
    const Session s = session();
    if (s.client)
    {
      s.client->stop();
    }
    if (s.link)
    {
      s.link->interrupt();
    }
  }

  Session session()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return session_;
  }

  // A running client, or an error message for a service or action.
  std::shared_ptr<ethernut::Client> client(std::string& why)
  {
    const Session s = session();
    if (!s.client || s.client->state() == ethernut::SessionState::kDisconnected ||
        s.client->state() == ethernut::SessionState::kInitialising)
    {
      why = "not connected to the ethernut board at " + host_ + ":" + std::to_string(port_);
      return nullptr;
    }
    return s.client;
  }

  // ------------------------------------------------------------------------- listener (run() thread)
  void onState(ethernut::SessionState st, ethernut::SessionState) override
  {
    const Session s = session();
    const ethernut::BoardMode mode = s.client ? s.client->mode() : ethernut::BoardMode::kUnknown;
    state_->update(
        [&](MachineState& m)
        {
          m.mode = stateMode(mode);
          switch (st)
          {
            case ethernut::SessionState::kSending:
            case ethernut::SessionState::kWaitingReady:
              m.execution = MachineState::EXECUTION_ACTIVE;
              break;
            case ethernut::SessionState::kReadyToSend:
              m.execution =
                  s.client && s.client->jobActive() ? MachineState::EXECUTION_ACTIVE : MachineState::EXECUTION_READY;
              break;
            case ethernut::SessionState::kConnected:
              m.execution = MachineState::EXECUTION_READY;
              break;
            case ethernut::SessionState::kPaused:
              m.execution = MachineState::EXECUTION_PAUSED;
              break;
            case ethernut::SessionState::kKilled:
              m.execution = MachineState::EXECUTION_STOPPED;
              m.message = "killed";
              break;
            case ethernut::SessionState::kStandalone:
              m.mode = MachineState::MODE_AUTO;
              m.execution = MachineState::EXECUTION_UNKNOWN;
              m.message = "board in standalone mode (call ~set_mode to reconnect)";
              break;
            default:
              m.execution = MachineState::EXECUTION_UNKNOWN;
              break;
          }
        });
  }

  void onPosition(float x, float y, float z) override
  {
    // Status-4 messages are the machine's reported position, mm.
    state_->setPosition(x * kMetresPerMm, y * kMetresPerMm, z * kMetresPerMm);
  }

  void onCoordinateDone(uint64_t index, const ethernut::Coordinate& c) override
  {
    {
      std::lock_guard<std::mutex> lock(job_mutex_);
      job_.done = index + 1;
      job_.line = c.tag;
      job_.last = c;
    }
    // The set the board acknowledged (NEXT) is the commanded position; status-4 reports are where
    // the machine is.
    state_->setCommandedPosition(c.x * kMetresPerMm, c.y * kMetresPerMm, c.z * kMetresPerMm);
  }

  void onResend(uint64_t, unsigned) override
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    ++job_.resends;
  }

  void onJobFinished(ethernut::JobOutcome outcome, const std::string& message) override
  {
    {
      std::lock_guard<std::mutex> lock(job_mutex_);
      job_.finished = true;
      job_.outcome = outcome;
      job_.message = message;
    }
    job_cv_.notify_all();
    if (outcome == ethernut::JobOutcome::kCompleted && segment_continues_)
    {
      return;  // the program goes on after one of its own steps: the job runs on
    }
    // A job cancelled by ~run_job's cancel leaves the board paused (the held move): say so.
    const Session s = session();
    const bool paused = s.client && s.client->state() == ethernut::SessionState::kPaused;
    state_->update(
        [&](MachineState& m)
        {
          m.execution = paused ? MachineState::EXECUTION_PAUSED
                               : (outcome == ethernut::JobOutcome::kCompleted ? MachineState::EXECUTION_READY
                                                                              : MachineState::EXECUTION_STOPPED);
          m.message = message;
        });
  }

  void onBoardError(float code) override
  {
    state_->update([&](MachineState& m) { m.message = "board error code " + std::to_string(static_cast<int>(code)); });
  }

  // ------------------------------------------------------------------------- jobs
  struct JobProgress
  {
    uint64_t done = 0;
    uint32_t line = 0;
    uint32_t resends = 0;
    ethernut::Coordinate last;
    bool finished = false;
    ethernut::JobOutcome outcome = ethernut::JobOutcome::kFailed;
    std::string message;
  };

  // The preview of a job: poses of job/path and the rapid/feed line lists of job/markers.
  class Preview
  {
   public:
    Preview(size_t max_points, const std::string& frame) : max_points_(max_points)
    {
      path_.header.frame_id = frame;
      path_.header.stamp = ros::Time::now();
    }
    void add(double x_mm, double y_mm, double z_mm, bool rapid)
    {
      if (count_++ % stride_ != 0)
      {
        return;
      }
      geometry_msgs::PoseStamped pose;
      pose.header = path_.header;
      pose.pose.position.x = x_mm * kMetresPerMm;
      pose.pose.position.y = y_mm * kMetresPerMm;
      pose.pose.position.z = z_mm * kMetresPerMm;
      pose.pose.orientation.w = 1.0;
      path_.poses.push_back(pose);
      rapid_.push_back(rapid);
      if (path_.poses.size() >= max_points_)
      {
        // Thin to every other pose and keep one in 2*stride from now on: memory stays bounded.
        size_t kept = 0;
        for (size_t i = 0; i < path_.poses.size(); i += 2)
        {
          path_.poses[kept] = path_.poses[i];
          rapid_[kept] = rapid_[i];
          ++kept;
        }
        path_.poses.resize(kept);
        rapid_.resize(kept);
        stride_ *= 2;
      }
    }
    const nav_msgs::Path& path() const { return path_; }
    visualization_msgs::MarkerArray markers() const
    {
      visualization_msgs::MarkerArray array;
      visualization_msgs::Marker clear;
      clear.action = visualization_msgs::Marker::DELETEALL;
      array.markers.push_back(clear);
      for (int rapid = 0; rapid < 2; ++rapid)
      {
        visualization_msgs::Marker m;
        m.header = path_.header;
        m.ns = rapid ? "rapid" : "feed";
        m.id = rapid;
        m.type = visualization_msgs::Marker::LINE_LIST;
        m.action = visualization_msgs::Marker::ADD;
        m.pose.orientation.w = 1.0;
        m.scale.x = rapid ? 0.0003 : 0.0005;  // line width, m
        // Feeds green, rapids orange: the colours CAM previews use for cutting and positioning.
        m.color.r = rapid ? 1.0f : 0.1f;
        m.color.g = rapid ? 0.55f : 0.8f;
        m.color.b = rapid ? 0.0f : 0.2f;
        m.color.a = 1.0f;
        for (size_t i = 1; i < path_.poses.size(); ++i)
        {
          if (static_cast<bool>(rapid_[i]) == static_cast<bool>(rapid))
          {
            m.points.push_back(path_.poses[i - 1].pose.position);
            m.points.push_back(path_.poses[i].pose.position);
          }
        }
        // rviz refuses an empty line list (and shows the display in error); DELETEALL cleared it.
        if (!m.points.empty())
          array.markers.push_back(m);
      }
      return array;
    }

   private:
    size_t max_points_;
    size_t stride_ = 1;
    size_t count_ = 0;
    nav_msgs::Path path_;
    std::vector<uint8_t> rapid_;
  };

  void execute(const RunJobGoalConstPtr& goal)
  {
    RunJobResult result;
    auto abort = [&](const std::string& message)
    {
      result.success = false;
      result.message = message;
      ROS_WARN_STREAM("run_job: " << message);
      action_.setAborted(result, message);
    };
    if (!motion_->enabled())
    {
      abort(motion_->refusal("job"));  // before anything is loaded or sent
      return;
    }
    std::string why;
    auto c = client(why);
    if (!c)
    {
      abort(why);
      return;
    }
    const GoalScope goal_scope(*this);
    if (c->state() == ethernut::SessionState::kPaused)
    {
      abort("the board is paused (a cancelled job holds its move there): call " + pnh_.resolveName("resume") +
            " first");
      return;
    }

    // Load the job: a first pass over the file counts the coordinates and builds the preview, so
    // the preview is out before the first set is sent and a bad program is refused before it runs.
    Preview preview(static_cast<size_t>(max_preview_points_), state_->frame("machine"));
    std::function<bool(ethernut::Coordinate&)> source;
    // The program step the stream stopped at when a segment of moves ended (none for points).
    std::function<std::optional<gcode::ProgramStep>()> step_at_end = [] { return std::nullopt; };
    uint64_t count = 0;
    std::string program;
    std::string skipped_note;  // G53 moves left out
    const std::string machine_frame = state_->frame("machine");
    if (!goal->file.empty())
    {
      if (!goal->header.frame_id.empty() && goal->header.frame_id != machine_frame)
      {
        // A program's coordinates are its own work coordinates, streamed as they are.
        abort("job refused: a G-code job is streamed in the program's coordinates; header.frame_id (\"" +
              goal->header.frame_id + "\") applies to points only and must be empty or \"" + machine_frame + "\"");
        return;
      }
      if (!program_dir_)
      {
        abort("G-code jobs need ~program_dir (" + pnh_.resolveName("program_dir") + ")");
        return;
      }
      std::string path;
      try
      {
        path = program_dir_->resolveExisting(goal->file);
        GcodeJob job(path, parser_options_, g53_moves_, pnh_.resolveName("g53_moves"));
        gcode::Move move;
        bool first_move = true;
        Preview fresh(static_cast<size_t>(max_preview_points_), state_->frame("machine"));
        // Every move up to the program's end (M02/M30): what comes after it is never sent.
        for (;;)
        {
          if (!job.next(move))
          {
            if (job.step())
            {
              continue;
            }
            break;
          }
          if (first_move)
          {
            fresh.add(move.start.x, move.start.y, move.start.z, true);
            first_move = false;
          }
          fresh.add(move.end.x, move.end.y, move.end.z, move.motion == gcode::Motion::kRapid);
          ++count;
        }
        preview = std::move(fresh);
        skipped_note = job.skippedSummary();
        if (!skipped_note.empty())
        {
          ROS_WARN_STREAM("run_job: " << goal->file << ": " << skipped_note << " (" << pnh_.resolveName("g53_moves")
                                      << ": skip)");
        }
      }
      catch (const Error& e)
      {
        abort(std::string("job refused: ") + e.what());
        return;
      }
      program = goal->file;
      auto job = std::make_shared<GcodeJob>(path, parser_options_, g53_moves_, pnh_.resolveName("g53_moves"));
      step_at_end = [job] { return job->step(); };
      source = [this, job](ethernut::Coordinate& out)
      {
        gcode::Move move;
        if (!job->next(move))
        {
          // The stream pauses at a program step (not the end): the segment's end is not the job's.
          segment_continues_ = job->step() && job->step()->kind != gcode::ProgramStep::Kind::kEnd;
          return false;
        }
        out.x = static_cast<float>(move.end.x);
        out.y = static_cast<float>(move.end.y);
        out.z = static_cast<float>(move.end.z);
        out.tag = move.line;
        return true;
      };
    }
    else
    {
      if (goal->points.empty())
      {
        abort("job refused: neither a file nor points given");
        return;
      }
      // Points in another frame (the cell's world, a robot's base) into the machine frame.
      ToMachineFrame::Transform transform;
      try
      {
        transform = to_machine_->lookup(machine_frame, goal->header.frame_id, "points");
      }
      catch (const Error& e)
      {
        abort(std::string("job refused: ") + e.what());
        return;
      }
      auto points = std::make_shared<std::vector<ethernut::Coordinate>>();
      for (const auto& given : goal->points)
      {
        const geometry_msgs::Point p = ToMachineFrame::apply(transform, given);
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        {
          abort("job refused: point " + std::to_string(points->size()) + " is not finite");
          return;
        }
        ethernut::Coordinate c;
        c.x = static_cast<float>(p.x / kMetresPerMm);
        c.y = static_cast<float>(p.y / kMetresPerMm);
        c.z = static_cast<float>(p.z / kMetresPerMm);
        points->push_back(c);
        preview.add(c.x, c.y, c.z, false);
      }
      count = points->size();
      program = "(points)";
      auto next = std::make_shared<size_t>(0);
      source = [points, next](ethernut::Coordinate& out)
      {
        if (*next >= points->size())
        {
          return false;
        }
        out = (*points)[(*next)++];
        return true;
      };
    }
    path_pub_.publish(preview.path());
    markers_pub_.publish(preview.markers());
    state_->update(
        [&](MachineState& m)
        {
          m.program = program;
          m.block = 0;
        });

    ROS_INFO_STREAM("run_job: streaming " << count << " coordinates of " << program);
    // The job runs as segments: the moves up to the program's next own step (stop, dwell, spindle,
    // coolant, tool change), which the node carries out between two segments, or its end.
    RunJobFeedback feedback;
    feedback.coordinate_count = static_cast<uint32_t>(count);
    Totals totals;
    bool cancelled = false;
    for (;;)
    {
      {
        std::lock_guard<std::mutex> lock(job_mutex_);
        job_ = JobProgress();
      }
      segment_continues_ = false;
      try
      {
        if (!startSegment(*c, source, feedback, cancelled))
        {
          result.coordinates_done = static_cast<uint32_t>(totals.done);
          result.coordinate_count = static_cast<uint32_t>(count);
          result.resends = totals.resends;
          result.message = "cancelled while held (" + feedback.event + ")";
          action_.setPreempted(result, result.message);
          return;
        }
      }
      catch (const Error& e)
      {
        abort(e.what());
        return;
      }
      const JobProgress p = followSegment(*c, feedback, count, totals, cancelled);
      totals.done += p.done;
      totals.resends += p.resends;
      const auto step = p.outcome == ethernut::JobOutcome::kCompleted ? step_at_end() : std::nullopt;
      if (step && step->kind != gcode::ProgramStep::Kind::kEnd)
      {
        if (!carryOut(*step, feedback, cancelled))
        {
          result.coordinates_done = static_cast<uint32_t>(totals.done);
          result.coordinate_count = static_cast<uint32_t>(count);
          result.resends = totals.resends;
          result.message = "cancelled at the " + step->describe();
          state_->update(
              [&](MachineState& m)
              {
                m.execution = MachineState::EXECUTION_STOPPED;
                m.message = result.message;
              });
          action_.setPreempted(result, result.message);
          return;
        }
        continue;
      }
      result.coordinates_done = static_cast<uint32_t>(totals.done);
      result.coordinate_count = static_cast<uint32_t>(count);
      result.resends = totals.resends;
      result.message = step ? step->describe() + ": the job ends here; nothing after it was sent" : p.message;
      if (!skipped_note.empty())
      {
        result.message += "; " + skipped_note;
      }
      result.success = p.outcome == ethernut::JobOutcome::kCompleted;
      if (step)
      {
        state_->update([&](MachineState& m) { m.message = result.message; });
      }
      if (cancelled)
      {
        action_.setPreempted(result, result.message);
      }
      else if (result.success)
      {
        action_.setSucceeded(result, result.message);
      }
      else
      {
        abort(result.message);
      }
      return;
    }
  }

  // Marks the node's one goal as running (a disable then holds it) for the scope of execute().
  class GoalScope
  {
   public:
    explicit GoalScope(EthernutNode& node) : node_(node) { set(true); }
    ~GoalScope() { set(false); }
    GoalScope(const GoalScope&) = delete;
    GoalScope& operator=(const GoalScope&) = delete;

   private:
    void set(bool running)
    {
      std::lock_guard<std::mutex> lock(node_.job_mutex_);
      node_.goal_running_ = running;
      node_.motion_hold_.clear();
    }
    EthernutNode& node_;
  };

  // Starts the next segment of moves once motion is allowed: enabled, and no hold left from a
  // disable during this job (~resume, refused while motion is disabled, ends the hold). The check
  // and the start are one step under motion_mutex_, so a disable either comes before (the job is
  // held here) or after (it pauses the board). \returns false if the goal was cancelled while held.
  // \throws Error from Client::startJob.
  bool startSegment(ethernut::Client& c, const std::function<bool(ethernut::Coordinate&)>& source,
                    RunJobFeedback& feedback, bool& cancelled)
  {
    for (;;)
    {
      std::string hold;
      uint64_t resumes = 0;
      {
        std::lock_guard<std::mutex> gate(motion_mutex_);
        {
          std::lock_guard<std::mutex> lock(job_mutex_);
          hold = motion_hold_;
          resumes = resume_count_;
        }
        if (motion_->enabled() && hold.empty())
        {
          c.startJob(source);
          return true;
        }
      }
      if (hold.empty())
      {
        hold = "motion disabled";  // onMotionSwitched has not run yet; it names the caller
      }
      showMotionHold(hold, "", false, feedback);
      state_->update([&](MachineState& m) { m.execution = MachineState::EXECUTION_PAUSED; });
      if (!waitForResume(resumes, cancelled))
      {
        return false;
      }
      showMotionHold("", hold, false, feedback);
      state_->update([&](MachineState& m) { m.execution = MachineState::EXECUTION_ACTIVE; });
    }
  }

  // Feedback (and state's message) for a motion hold that began (\p hold) or ended (\p hold empty,
  // \p ended the hold that ended).
  void showMotionHold(const std::string& hold, const std::string& ended, bool board_holds, RunJobFeedback& feedback)
  {
    feedback.paused = !hold.empty();
    if (hold.empty())
    {
      feedback.event = "resumed after the hold (" + ended + ")";
    }
    else
    {
      feedback.event = hold + ": " +
                       (board_holds ? "the board holds the move in progress" : "the job holds before its next move") +
                       "; enable motion with " + pnh_.resolveName("set_motion_enabled") +
                       " (std_srvs/SetBool, data: true), then call " + pnh_.resolveName("resume");
    }
    ROS_INFO_STREAM("run_job: " << feedback.event);
    state_->update([&](MachineState& m) { m.message = feedback.event; });
    action_.publishFeedback(feedback);
  }

  // Waits until ~resume succeeds after \p resumes resumes; false if the goal is cancelled first.
  bool waitForResume(uint64_t resumes, bool& cancelled)
  {
    std::unique_lock<std::mutex> lock(job_mutex_);
    while (resume_count_ == resumes)
    {
      lock.unlock();
      if (action_.isPreemptRequested() || !ros::ok())
      {
        cancelled = true;
        return false;
      }
      lock.lock();
      // Cancel comes without a notification here: look again at least every 20 ms.
      job_cv_.wait_for(lock, Milliseconds(20));
    }
    return true;
  }

  struct Totals
  {
    uint64_t done = 0;  // sets acknowledged in the segments before this one
    uint32_t resends = 0;
  };

  // Streams one segment to its end, with feedback at most every 50 ms (a fast board acknowledges
  // thousands of sets per second); a cancel holds the board, then stops streaming.
  JobProgress followSegment(ethernut::Client& c, RunJobFeedback& feedback, uint64_t count, const Totals& totals,
                            bool& cancelled)
  {
    uint64_t reported = UINT64_MAX;
    std::string shown_hold;  // the motion hold the last feedback showed
    for (;;)
    {
      std::unique_lock<std::mutex> lock(job_mutex_);
      job_cv_.wait_for(lock, std::chrono::milliseconds(50), [&] { return job_.finished; });
      const JobProgress p = job_;
      const std::string hold = motion_hold_;
      lock.unlock();
      if (hold != shown_hold && !p.finished)
      {
        showMotionHold(hold, shown_hold, true, feedback);
        shown_hold = hold;
      }
      if (p.done != reported && (p.done > 0 || totals.done == 0))
      {
        reported = p.done;
        const uint64_t done = totals.done + p.done;
        feedback.line = p.line;
        feedback.coordinate_index = done > 0 ? static_cast<uint32_t>(done - 1) : 0;
        feedback.percent = count > 0 ? static_cast<float>(100.0 * done / count) : 100.0f;
        feedback.resends = totals.resends + p.resends;
        feedback.commanded.x = p.last.x * kMetresPerMm;
        feedback.commanded.y = p.last.y * kMetresPerMm;
        feedback.commanded.z = p.last.z * kMetresPerMm;
        feedback.paused = !shown_hold.empty();
        action_.publishFeedback(feedback);
        state_->update([&](MachineState& m) { m.block = p.line; });
      }
      if (p.finished)
      {
        return p;
      }
      if (!cancelled && (action_.isPreemptRequested() || !ros::ok()))
      {
        cancelled = true;
        // Cancel: hold the board first (it stops the move in progress), then stop streaming.
        try
        {
          c.pause();
        }
        catch (const Error& e)
        {
          ROS_WARN_STREAM("run_job: pause on cancel failed: " << e.what());
        }
        c.cancelJob();
      }
    }
  }

  // Carries out one of the program's own steps between two segments (every set before it is
  // acknowledged: the board has moved there). \returns false if the goal was cancelled meanwhile.
  bool carryOut(const gcode::ProgramStep& step, RunJobFeedback& feedback, bool& cancelled)
  {
    using Kind = gcode::ProgramStep::Kind;
    feedback.event = step.describe();
    feedback.line = step.line;
    switch (step.kind)
    {
      case Kind::kToolChange:
        state_->update([&](MachineState& m) { m.tool = step.tool; });
        break;
      case Kind::kSpindle:
        state_->update([&](MachineState& m)
                       { m.spindle_speed = step.spindle == gcode::Spindle::kOff ? 0.0 : step.spindle_rpm; });
        break;
      case Kind::kCoolant:
        state_->update([&](MachineState& m)
                       { m.coolant = step.coolant ? MachineState::COOLANT_ON : MachineState::COOLANT_OFF; });
        break;
      case Kind::kDwell:
        state_->update([&](MachineState& m) { m.message = step.describe(); });
        action_.publishFeedback(feedback);
        return waitWhileRunning(std::chrono::duration<double>(step.dwell_s), false, cancelled);
      case Kind::kOptionalStop:
        // Read at each M01, as an operator flips the control's OPT STOP switch during a job.
        if (!pnh_.param("optional_stop", true))
        {
          feedback.event += " passed (" + pnh_.resolveName("optional_stop") + " false)";
          action_.publishFeedback(feedback);
          return true;
        }
        [[fallthrough]];
      case Kind::kStop:
      {
        feedback.event += ": waiting for " + pnh_.resolveName("resume");
        feedback.paused = true;
        {
          std::lock_guard<std::mutex> lock(job_mutex_);
          program_stop_ = step.describe();
          resume_requested_ = false;
        }
        state_->update(
            [&](MachineState& m)
            {
              m.execution = MachineState::EXECUTION_PAUSED;
              m.block = step.line;
              m.message = feedback.event;
            });
        ROS_INFO_STREAM("run_job: " << feedback.event);
        action_.publishFeedback(feedback);
        const bool resumed = waitWhileRunning(std::chrono::hours(24 * 365), true, cancelled);
        {
          std::lock_guard<std::mutex> lock(job_mutex_);
          program_stop_.clear();
        }
        feedback.paused = false;
        if (resumed)
        {
          state_->update(
              [&](MachineState& m)
              {
                m.execution = MachineState::EXECUTION_ACTIVE;
                m.message = "resumed after the " + step.describe();
              });
        }
        return resumed;
      }
      default:
        break;
    }
    action_.publishFeedback(feedback);
    return true;
  }

  // Waits for \p time, or (\p until_resume) for ~resume; false if the goal is cancelled first.
  bool waitWhileRunning(std::chrono::duration<double> time, bool until_resume, bool& cancelled)
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
      if (action_.isPreemptRequested() || !ros::ok())
      {
        cancelled = true;
        return false;
      }
      lock.lock();
      // Cancel comes without a notification here: look again at least every 20 ms.
      job_cv_.wait_until(lock, std::min(deadline, std::chrono::steady_clock::now() + Milliseconds(20)));
    }
  }

  // ------------------------------------------------------------------------- services
  template <typename F>
  bool command(std_srvs::Trigger::Response& res, const char* what, F f)
  {
    std::string why;
    auto c = client(why);
    if (!c)
    {
      res.success = false;
      res.message = why;
      return true;
    }
    try
    {
      f(*c);
      res.success = true;
      res.message = what;
    }
    catch (const Error& e)
    {
      res.success = false;
      res.message = e.what();
    }
    return true;
  }

  bool onPause(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    return command(res, "paused", [](ethernut::Client& c) { c.pause(); });
  }
  // ~resume: lets a held move go on (the board paused by ~pause, a cancel or a disable), a job on
  // after the program's M00/M01 or after a disable; refused while motion is disabled.
  bool onResume(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    std::lock_guard<std::mutex> gate(motion_mutex_);
    if (!motion_->enabled())
    {
      res.success = false;
      res.message = motion_->refusal("resume");
      return true;
    }
    std::string held;  // what the job waited at
    {
      std::lock_guard<std::mutex> lock(job_mutex_);
      if (!program_stop_.empty())
      {
        resume_requested_ = true;  // the board itself was never paused at a program stop
        held = "the " + program_stop_;
      }
      if (!motion_hold_.empty())
      {
        held += (held.empty() ? "the hold (" : " and the hold (") + motion_hold_ + ")";
        motion_hold_.clear();
      }
      ++resume_count_;
    }
    job_cv_.notify_all();
    std::string why;
    const auto c = client(why);
    if (held.empty() || (c && c->state() == ethernut::SessionState::kPaused))
    {
      command(res, "resumed", [](ethernut::Client& board) { board.resume(); });
      if (!res.success)
      {
        return true;
      }
    }
    if (!held.empty())
    {
      res.success = true;
      res.message = "resumed after " + held;
    }
    return true;
  }

  // ~set_motion_enabled: disabling pauses a running job (the board holds the move in progress,
  // as for a cancel) and holds the goal until motion is enabled again and ~resume is called.
  void onMotionSwitched(bool enabled, const std::string& caller)
  {
    std::string what = std::string("motion ") + (enabled ? "enabled" : "disabled") + " by " + caller;
    std::lock_guard<std::mutex> gate(motion_mutex_);
    bool running = false;
    {
      std::lock_guard<std::mutex> lock(job_mutex_);
      running = goal_running_;
      if (!enabled && running && motion_hold_.empty())
      {
        motion_hold_ = what;
      }
      if (enabled && !motion_hold_.empty())
      {
        what += "; the job stays held until " + pnh_.resolveName("resume");  // enabling alone moves nothing
      }
    }
    job_cv_.notify_all();
    state_->update([&](MachineState& m) { m.message = what; });
    if (enabled || !running)
    {
      return;
    }
    std::string why;
    const auto c = client(why);
    if (!c || !c->jobActive())
    {
      return;  // between two segments of the job, or not connected: nothing streams
    }
    try
    {
      c->pause();
    }
    catch (const Error& e)
    {
      // The board did not confirm the pause: stop streaming at least (the job then ends).
      ROS_ERROR_STREAM("run_job: pause on disable failed (" << e.what() << "): streaming stopped");
      c->cancelJob();
    }
  }

  bool onReset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    return command(res, "reset: job cancelled, board cleared to 0/0/0", [](ethernut::Client& c) { c.reset(); });
  }
  bool onKill(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res)
  {
    if (!kill_->enabled())
    {
      res.success = false;
      res.message = kill_->refusal("kill") + " (or PROG_CNCkill|1 in ~settings_file)";
      return true;
    }
    return command(res, "killed: the board stopped and dropped the link", [](ethernut::Client& c) { c.kill(); });
  }

  bool onSetMode(EthernutSetMode::Request& req, EthernutSetMode::Response& res)
  {
    ethernut::BoardMode mode;
    if (!parseMode(req.mode, mode))
    {
      res.success = false;
      res.message = "unknown mode '" + req.mode + "' (file, gui-control or standalone)";
      return true;
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      options_.initial_mode = mode;  // also the mode after the next reconnection
      if (hold_)
      {
        if (mode == ethernut::BoardMode::kStandalone)
        {
          res.success = true;
          res.message = "already in standalone mode";
          return true;
        }
        hold_ = false;
        hold_cv_.notify_all();
        res.success = true;
        res.message = std::string("reconnecting in ") + ethernut::toString(mode) + " mode";
        return true;
      }
    }
    std::string why;
    auto c = client(why);
    if (!c)
    {
      res.success = false;
      res.message = why;
      return true;
    }
    try
    {
      c->setMode(mode);
      res.success = true;
      res.message = std::string("mode ") + ethernut::toString(mode);
      state_->update([&](MachineState& m) { m.mode = stateMode(mode); });
    }
    catch (const Error& e)
    {
      res.success = false;
      res.message = e.what();
    }
    return true;
  }

  void protocolDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
  {
    const Session s = session();
    if (!s.client)
    {
      status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "not connected yet");
      return;
    }
    const ethernut::ClientStats st = s.client->stats();  // round trips: this connection
    ethernut::ClientStats total;                         // counters: since the node started
    {
      std::lock_guard<std::mutex> lock(mutex_);
      total = earlier_sessions_;
    }
    addCounts(total, st);
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, ethernut::toString(s.client->state()));
    if (st.last_board_error != 0.0f)
    {
      status.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "the board reported an error code");
    }
    status.add("session state", ethernut::toString(s.client->state()));
    status.add("board mode", ethernut::toString(s.client->mode()));
    // Link: alive request -> response. Coordinate: set sent -> NEXT, which includes the move.
    status.add("link round trip last (ms)", st.last_link_rtt_ms);
    status.add("link round trip mean (ms)", st.mean_link_rtt_ms);
    status.add("link round trip max (ms)", st.max_link_rtt_ms);
    status.add("link round trip samples", st.alive_responses);
    status.add("coordinate round trip last (ms)", st.last_rtt_ms);
    status.add("coordinate round trip mean (ms)", st.mean_rtt_ms);
    status.add("coordinate round trip max (ms)", st.max_rtt_ms);
    status.add("coordinates sent", total.coordinates_sent);
    status.add("coordinates acknowledged", total.coordinates_done);
    status.add("resends", total.resends);
    status.add("keepalive requests", total.keepalive_requests);
    status.add("keepalive misses", total.keepalive_misses);
    status.add("invalid frames", total.bad_frames);
    status.add("unexpected messages", total.unexpected_messages);
    status.add("last board error code", st.last_board_error);
    status.add("reconnects", reconnector_ ? reconnector_->reconnects() : 0u);
    kill_->addTo(status);
    motion_->addTo(status);
  }

  ros::NodeHandle nh_;
  ros::NodeHandle pnh_;
  std::string host_;
  uint16_t port_ = 6666;
  Milliseconds connect_timeout_{3000};
  ethernut::ClientOptions options_;
  std::unique_ptr<RuntimeSwitch> kill_;
  std::unique_ptr<RuntimeSwitch> motion_;
  std::mutex motion_mutex_;  // a segment's start, a disable's pause and ~resume: one at a time
  std::unique_ptr<ProgramDirectory> program_dir_;
  std::unique_ptr<ToMachineFrame> to_machine_;
  gcode::ParserOptions parser_options_;
  G53Moves g53_moves_ = G53Moves::kRefuse;
  int max_preview_points_ = 100000;

  std::unique_ptr<MachineStatePublisher> state_;
  ros::Publisher path_pub_;
  ros::Publisher markers_pub_;
  ros::ServiceServer pause_srv_, resume_srv_, reset_srv_, kill_srv_, mode_srv_;
  SingleGoalActionServer<RunJobAction> action_;

  std::mutex mutex_;  // session_, hold_, stopping_, options_.initial_mode
  std::condition_variable hold_cv_;
  Session session_;
  ethernut::ClientStats earlier_sessions_;  // counters of the connections before session_
  bool hold_ = false;
  bool stopping_ = false;

  std::mutex job_mutex_;
  std::condition_variable job_cv_;
  JobProgress job_;
  std::string program_stop_;                    // the M00/M01 the job waits at ("" when none), under job_mutex_
  bool resume_requested_ = false;               // ~resume called while waiting there, under job_mutex_
  bool goal_running_ = false;                   // execute() runs a goal, under job_mutex_
  std::string motion_hold_;                     // "motion disabled by ..." holding the goal, under job_mutex_
  uint64_t resume_count_ = 0;                   // successful ~resume calls, under job_mutex_
  std::atomic<bool> segment_continues_{false};  // the segment streaming ended at a program step

  std::unique_ptr<Reconnector> reconnector_;
};
}  // namespace cnc_bridge

// Four threads, serving from the start: services and the action may wait for the board concurrently.
int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::EthernutNode>(argc, argv, "ethernut_node", {4, true});
}
