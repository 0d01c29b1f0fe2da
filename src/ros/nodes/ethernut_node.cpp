// ethernut_node (src/ros/nodes/ethernut_node.h): parameters, the link to the board, the
// job preview as ROS messages and diagnostics. The client's events and the services:
// ethernut_services.cpp; the ~run_job action: ethernut_jobs.cpp.
#include "ethernut_node.h"

#include <nav_msgs/Path.h>
#include <visualization_msgs/MarkerArray.h>

#include <cmath>

#include "cnc_bridge/ros/gcode_params.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/ros/request_boundary.h"

namespace cnc_bridge
{
namespace
{
nav_msgs::Path pathOf(const ethernut::Preview& preview, const std::string& frame)
{
  nav_msgs::Path path;
  path.header.frame_id = frame;
  path.header.stamp = ros::Time::now();
  path.poses.reserve(preview.points().size());
  for (const ethernut::PreviewPoint& point : preview.points())
  {
    geometry_msgs::PoseStamped pose;
    pose.header = path.header;
    pose.pose.position.x = point.x * EthernutNode::kMetresPerMm;
    pose.pose.position.y = point.y * EthernutNode::kMetresPerMm;
    pose.pose.position.z = point.z * EthernutNode::kMetresPerMm;
    pose.pose.orientation.w = 1.0;
    path.poses.push_back(pose);
  }
  return path;
}

// The lines of \p path reached by rapid moves (\p rapid) or by feed moves, as one line list.
visualization_msgs::Marker lineList(const nav_msgs::Path& path, const ethernut::Preview& preview, bool rapid)
{
  visualization_msgs::Marker m;
  m.header = path.header;
  m.ns = rapid ? "rapid" : "feed";
  m.id = rapid ? 1 : 0;
  m.type = visualization_msgs::Marker::LINE_LIST;
  m.action = visualization_msgs::Marker::ADD;
  m.pose.orientation.w = 1.0;
  m.scale.x = rapid ? 0.0003 : 0.0005;  // line width, m
  // Feeds green, rapids orange: the colours CAM previews use for cutting and positioning.
  m.color.r = rapid ? 1.0f : 0.1f;
  m.color.g = rapid ? 0.55f : 0.8f;
  m.color.b = rapid ? 0.0f : 0.2f;
  m.color.a = 1.0f;
  for (size_t i = 1; i < path.poses.size(); ++i)
  {
    if (preview.points()[i].rapid == rapid)
    {
      m.points.push_back(path.poses[i - 1].pose.position);
      m.points.push_back(path.poses[i].pose.position);
    }
  }
  return m;
}

visualization_msgs::MarkerArray markersOf(const nav_msgs::Path& path, const ethernut::Preview& preview)
{
  visualization_msgs::MarkerArray array;
  visualization_msgs::Marker clear;
  clear.action = visualization_msgs::Marker::DELETEALL;
  array.markers.push_back(clear);
  for (const bool rapid : {false, true})
  {
    visualization_msgs::Marker lines = lineList(path, preview, rapid);
    // rviz refuses an empty line list (and shows the display in error); DELETEALL cleared it.
    if (!lines.points.empty())
    {
      array.markers.push_back(lines);
    }
  }
  return array;
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
  motion_ = std::make_unique<RuntimeSwitch>(pnh_, "motion", "enable_motion", "set_motion_enabled");
  jobs_ = std::make_unique<ethernut::JobStreamer>(
      motion_->core(), JobRunner::Names{pnh_.resolveName("resume"), pnh_.resolveName("set_motion_enabled"),
                                        pnh_.resolveName("optional_stop")});
  // Once the job streamer exists: a disable pauses a running job and holds it.
  motion_->core().subscribe([this](bool enabled, const std::string& caller) { onMotionSwitched(enabled, caller); });
  state_->diagnostics().add("ethernut protocol", this, &EthernutNode::protocolDiagnostics);
  path_pub_ = nh_.advertise<nav_msgs::Path>("job/path", 1, true);
  markers_pub_ = nh_.advertise<visualization_msgs::MarkerArray>("job/markers", 1, true);
  pause_srv_ = advertiseGuardedService(pnh_, "pause", &EthernutNode::onPause, this);
  resume_srv_ = advertiseGuardedService(pnh_, "resume", &EthernutNode::onResume, this);
  clear_srv_ = advertiseGuardedService(pnh_, "clear", &EthernutNode::onClear, this);
  reset_srv_ = advertiseGuardedService(pnh_, "reset", &EthernutNode::onReset, this);
  sync_oled_srv_ = advertiseGuardedService(pnh_, "sync_oled", &EthernutNode::onSyncOled, this);
  board_command_srv_ = advertiseGuardedService(pnh_, "board_command", &EthernutNode::onBoardCommand, this);
  kill_srv_ = advertiseGuardedService(pnh_, "kill", &EthernutNode::onKill, this);
  mode_srv_ = advertiseGuardedService(pnh_, "set_mode", &EthernutNode::onSetMode, this);
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
  link_->stop();
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
      throw params::MissingParameter(pnh_, "host", "nor INET_ADD in ~settings_file");
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
  // ~soft_limits ({x: [min, max], ...} m, machine frame): every coordinate of a job is checked
  // against them before the job's first set is sent; not set: no soft limits.
  soft_limits_ = params::softLimits(pnh_);
}

// ------------------------------------------------------------------------- link
void EthernutNode::startLink()
{
  link_ = std::make_unique<ReconnectingLink>(
      "ethernut " + host_ + ":" + std::to_string(port_), [this] { return connect(); },
      Backoff(Milliseconds(200), Milliseconds(5000)));
  link_->start([this](Transport&) { runSession(); }, state_->linkStateHandler());
}

// Opens the connection and the client on it: the client is the session's, kept with its
// connection in session_ for the services and the job thread.
std::shared_ptr<Transport> EthernutNode::connect()
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
  return link;
}

void EthernutNode::runSession()
{
  const Session s = session();
  s.client->run();
  if (reset_requested_.exchange(false))
  {
    // The end of the session closes the connection, as the qCNC's reset does; the link comes back
    // with the backoff, and the state says why it went.
    throw LinkError("reset: the connection was closed as ~reset does (the board cleared to 0/0/0); reconnecting");
  }
  if (s.client->state() == ethernut::SessionState::kStandalone)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    standalone_ = true;
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

// ------------------------------------------------------------------------- preview, diagnostics
void EthernutNode::publishPreview(const ethernut::Preview& preview)
{
  const nav_msgs::Path path = pathOf(preview, state_->frame("machine"));
  path_pub_.publish(path);
  markers_pub_.publish(markersOf(path, preview));
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
  status.add("reconnects", link_ ? link_->reconnects() : 0u);
  kill_->addTo(status);
  motion_->addTo(status);
}
}  // namespace cnc_bridge

// Four threads, serving from the start: services and the action may wait for the board concurrently.
int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::EthernutNode>(argc, argv, "ethernut_node", {4, true});
}
