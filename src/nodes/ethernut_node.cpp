// ethernut_node (include/cnc_bridge/ros/ethernut_node.h): parameters, the link to the board, the
// client's events as state, the services and diagnostics. The ~run_job action: ethernut_jobs.cpp.
#include "cnc_bridge/ros/ethernut_node.h"

#include <nav_msgs/Path.h>
#include <visualization_msgs/MarkerArray.h>

#include <cmath>

#include "cnc_bridge/ros/gcode_params.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
namespace
{
// The board's unit is the millimetre; messages are in metres.
constexpr double kMetresPerMm = 0.001;

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

uint8_t stateExecution(ethernut::SessionState st, bool job_active)
{
  switch (st)
  {
    case ethernut::SessionState::kSending:
    case ethernut::SessionState::kWaitingReady:
      return MachineState::EXECUTION_ACTIVE;
    case ethernut::SessionState::kReadyToSend:
      return job_active ? MachineState::EXECUTION_ACTIVE : MachineState::EXECUTION_READY;
    case ethernut::SessionState::kConnected:
      return MachineState::EXECUTION_READY;
    case ethernut::SessionState::kPaused:
      return MachineState::EXECUTION_PAUSED;
    case ethernut::SessionState::kKilled:
      return MachineState::EXECUTION_STOPPED;
    default:
      return MachineState::EXECUTION_UNKNOWN;
  }
}
}  // namespace

EthernutNode::EthernutNode(ros::NodeHandle nh, ros::NodeHandle pnh)
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
  startLink();
}

EthernutNode::~EthernutNode()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  standalone_cv_.notify_all();
  reconnector_->stop();
  action_.shutdown();
}

// ------------------------------------------------------------------------- parameters
void EthernutNode::readParameters()
{
  // ~settings_file (string, ""): a qCNC settings file (TSS, NAME|value); its INET_ADD, INET_PORT,
  // INET_DEL and PROG_CNCkill are used where the ROS parameters below are left empty/zero.
  pnh_.param<std::string>("settings_file", settings_file_, "");
  ethernut::Settings settings;
  if (!settings_file_.empty())
  {
    settings = ethernut::readSettingsFile(settings_file_);
  }
  readLinkParameters(settings);
  // ~enable_kill (bool, false) at start-up, ~set_kill_enabled at run time: allow ~kill (opcode
  // 99/99). PROG_CNCkill|1 in the settings file enables it too (qCNC enabled it by default; we
  // do not).
  kill_ = std::make_unique<RuntimeSwitch>(pnh_, "kill", "enable_kill", "set_kill_enabled");
  if (!kill_->enabled() && settings.kill_enabled.value_or(false))
  {
    kill_->set(true, "PROG_CNCkill|1 in " + settings_file_);
  }
  // The client's own gate stays open: the node's switch decides, and it changes at run time
  // while one client serves a whole connection.
  options_.kill_enabled = true;
  readJobParameters();
}

void EthernutNode::readLinkParameters(const ethernut::Settings& settings)
{
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
  const double dead = pnh_.param("dead_link_timeout", 0.0);
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
  const double probe = pnh_.param("rtt_probe_period", 5.0);
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
  options_.max_resends = static_cast<unsigned>(std::max(0, pnh_.param("max_resends", 5)));
  // ~ack_position_reports (bool, true): answer the board's position reports with an ack (Table 1).
  pnh_.param("ack_position_reports", options_.ack_position_reports, true);
  // ~mode (string, "file"): board mode selected on every connection: file, gui-control, standalone.
  const std::string mode = pnh_.param<std::string>("mode", "file");
  if (!ethernut::parseBoardMode(mode, options_.initial_mode))
  {
    throw ConfigError(pnh_.resolveName("mode") + " must be file, gui-control or standalone, not '" + mode + "'");
  }
}

void EthernutNode::readJobParameters()
{
  // ~program_dir (string, ""): directory G-code jobs are read from; empty: only point jobs.
  const std::string dir = pnh_.param<std::string>("program_dir", "");
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
  g53_ = ethernut::G53Policy{skip_g53 ? ethernut::G53Moves::kSkip : ethernut::G53Moves::kRefuse,
                             pnh_.resolveName("g53_moves")};
  // ~transform_timeout (s, 0.5): how long a points goal in another frame waits for its transform
  // into the machine frame.
  to_machine_ = std::make_unique<ToMachineFrame>(params::positive(pnh_, "transform_timeout", 0.5));
  // ~max_preview_points (int, 100000): job/path is thinned to at most this many poses.
  max_preview_points_ = std::max(pnh_.param("max_preview_points", 100000), 2);
}

// ------------------------------------------------------------------------- link
void EthernutNode::startLink()
{
  Reconnector::Callbacks callbacks;
  callbacks.connect = [this] { connect(); };
  callbacks.session = [this] { runSession(); };
  callbacks.on_state = [this](LinkState link, const std::string& why) { state_->setLink(link, why); };
  callbacks.disconnect = [this] { disconnect(); };
  reconnector_ = std::make_unique<Reconnector>("ethernut " + host_ + ":" + std::to_string(port_), callbacks,
                                               Backoff(Milliseconds(200), Milliseconds(5000)));
  reconnector_->start();
}

void EthernutNode::connect()
{
  ethernut::ClientOptions options;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    // Standalone mode: the board dropped us on purpose; wait for a request of another mode.
    standalone_cv_.wait(lock, [&] { return !standalone_ || stopping_; });
    if (stopping_)
    {
      throw CancelledError("stopping");
    }
    options = options_;
  }
  auto link = std::shared_ptr<TcpConnection>(TcpConnection::connect(host_, port_, connect_timeout_));
  auto client = std::make_shared<ethernut::Client>(*link, options, this);
  std::lock_guard<std::mutex> lock(mutex_);
  if (session_.client)
  {
    ethernut::addCounters(earlier_sessions_, session_.client->stats());  // diagnostics count since the start
  }
  session_ = Session{link, client};
}

void EthernutNode::runSession()
{
  const Session s = session();
  s.client->run();
  if (s.client->state() == ethernut::SessionState::kStandalone)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    standalone_ = true;
  }
}

void EthernutNode::disconnect()
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

EthernutNode::Session EthernutNode::session()
{
  std::lock_guard<std::mutex> lock(mutex_);
  return session_;
}

// A running client, or an error message for a service or action.
std::shared_ptr<ethernut::Client> EthernutNode::client(std::string& why)
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
void EthernutNode::onState(ethernut::SessionState st, ethernut::SessionState /*previous*/)
{
  const Session s = session();
  const ethernut::BoardMode mode = s.client ? s.client->mode() : ethernut::BoardMode::kUnknown;
  const bool job_active = s.client && s.client->jobActive();
  state_->update(
      [&](MachineState& m)
      {
        m.mode = stateMode(mode);
        m.execution = stateExecution(st, job_active);
        if (st == ethernut::SessionState::kKilled)
        {
          m.message = "killed";
        }
        if (st == ethernut::SessionState::kStandalone)
        {
          m.mode = MachineState::MODE_AUTO;
          m.message = "board in standalone mode (call ~set_mode to reconnect)";
        }
      });
}

void EthernutNode::onPosition(float x, float y, float z)
{
  // Status-4 messages are the machine's reported position, mm.
  state_->setPosition(x * kMetresPerMm, y * kMetresPerMm, z * kMetresPerMm);
}

void EthernutNode::onCoordinateDone(uint64_t index, const ethernut::Coordinate& c)
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

void EthernutNode::onResend(uint64_t /*index*/, unsigned /*count*/)
{
  std::lock_guard<std::mutex> lock(job_mutex_);
  ++job_.resends;
}

void EthernutNode::onJobFinished(ethernut::JobOutcome outcome, const std::string& message)
{
  bool segment_continues = false;
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    job_.finished = true;
    job_.outcome = outcome;
    job_.message = message;
    segment_continues = running_job_ && running_job_->segmentContinues();
  }
  job_cv_.notify_all();
  if (outcome == ethernut::JobOutcome::kCompleted && segment_continues)
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

void EthernutNode::onBoardError(float code)
{
  state_->update([&](MachineState& m) { m.message = "board error code " + std::to_string(static_cast<int>(code)); });
}

// ------------------------------------------------------------------------- services
template <typename F>
bool EthernutNode::command(std_srvs::Trigger::Response& res, const char* what, F f)
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

bool EthernutNode::onPause(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  return command(res, "paused", [](ethernut::Client& c) { c.pause(); });
}

// ~resume: lets a held move go on (the board paused by ~pause, a cancel or a disable), a job on
// after the program's M00/M01 or after a disable; refused while motion is disabled.
bool EthernutNode::onResume(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  std::lock_guard<std::mutex> gate(motion_mutex_);
  if (!motion_->enabled())
  {
    res.success = false;
    res.message = motion_->refusal("resume");
    return true;
  }
  const std::string held = releaseHolds();
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

// Ends the job's holds (the program's stop, a disable's hold); \returns what they were, "" for none.
std::string EthernutNode::releaseHolds()
{
  std::string held;
  if (const std::optional<std::string> stop = program_stop_.resume())
  {
    held = "the " + *stop;  // the board itself was never paused at a program stop
  }
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    if (!motion_hold_.empty())
    {
      held += (held.empty() ? "the hold (" : " and the hold (") + motion_hold_ + ")";
      motion_hold_.clear();
    }
    ++resume_count_;
  }
  job_cv_.notify_all();
  return held;
}

// ~set_motion_enabled: disabling pauses a running job (the board holds the move in progress,
// as for a cancel) and holds the goal until motion is enabled again and ~resume is called.
void EthernutNode::onMotionSwitched(bool enabled, const std::string& caller)
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

bool EthernutNode::onReset(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  return command(res, "reset: job cancelled, board cleared to 0/0/0", [](ethernut::Client& c) { c.reset(); });
}

bool EthernutNode::onKill(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  if (!kill_->enabled())
  {
    res.success = false;
    res.message = kill_->refusal("kill") + " (or PROG_CNCkill|1 in ~settings_file)";
    return true;
  }
  return command(res, "killed: the board stopped and dropped the link", [](ethernut::Client& c) { c.kill(); });
}

bool EthernutNode::onSetMode(EthernutSetMode::Request& req, EthernutSetMode::Response& res)
{
  ethernut::BoardMode mode = ethernut::BoardMode::kUnknown;
  if (!ethernut::parseBoardMode(req.mode, mode))
  {
    res.success = false;
    res.message = "unknown mode '" + req.mode + "' (file, gui-control or standalone)";
    return true;
  }
  if (leaveStandalone(mode, res))
  {
    return true;
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

// Makes \p mode the mode of the next connection; while the board is in standalone mode (and the
// node not connected), lets the node reconnect in it. \returns true if that answered the request.
bool EthernutNode::leaveStandalone(ethernut::BoardMode mode, EthernutSetMode::Response& res)
{
  std::lock_guard<std::mutex> lock(mutex_);
  options_.initial_mode = mode;  // also the mode after the next reconnection
  if (!standalone_)
  {
    return false;
  }
  res.success = true;
  if (mode == ethernut::BoardMode::kStandalone)
  {
    res.message = "already in standalone mode";
    return true;
  }
  standalone_ = false;
  standalone_cv_.notify_all();
  res.message = std::string("reconnecting in ") + ethernut::toString(mode) + " mode";
  return true;
}

void EthernutNode::protocolDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
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
  ethernut::addCounters(total, st);
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
}  // namespace cnc_bridge

// Four threads, serving from the start: services and the action may wait for the board concurrently.
int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::EthernutNode>(argc, argv, "ethernut_node", {4, true});
}
