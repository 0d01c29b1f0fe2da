// ethernut_node (src/ros/nodes/ethernut_node.h): the settings (ethernut_params.cpp) into the core
// session and job streamer, the job preview as ROS messages and diagnostics. The client's events
// and the services: ethernut_services.cpp; the ~run_job action: ethernut_jobs.cpp.
#include "ethernut_node.h"

#include <nav_msgs/Path.h>
#include <std_msgs/String.h>
#include <visualization_msgs/MarkerArray.h>

#include <cmath>

#include "cnc_bridge/ros/node_main.h"
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
      settings_(ethernut_params::read(pnh)),
      action_(
          pnh, "run_job", [this](const RunJobGoalConstPtr& goal) { execute(goal); },
          [](const RunJobGoal& goal)
          { return goal.file.empty() ? std::to_string(goal.points.size()) + " points" : "job " + goal.file; })
{
  // ~enable_kill (bool, false) at start-up, ~set_kill_enabled at run time: allow ~kill (opcode
  // 99/99); PROG_CNCkill|1 in the settings file enables it too.
  kill_ = std::make_unique<RuntimeSwitch>(pnh_, "kill", "enable_kill", "set_kill_enabled");
  if (!kill_->enabled() && !settings_.kill_enabled_by.empty())
  {
    kill_->set(true, settings_.kill_enabled_by);
  }
  if (!settings_.jobs.program_dir.empty())
  {
    program_dir_ = std::make_unique<ProgramDirectory>(settings_.jobs.program_dir);
  }
  to_machine_ = std::make_unique<ToMachineFrame>(settings_.transform_timeout);
  state_ = std::make_unique<MachineStatePublisher>(nh_, pnh_, settings_.session.link.hardwareId());
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
  board_ = std::make_unique<ethernut::BoardSession>(settings_.session, this);
  // Once the job streamer and the session exist: a disable pauses a running job and holds it.
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
  board_->start(state_->linkStateHandler());
  startDebugChannel();
}

EthernutNode::~EthernutNode()
{
  if (debug_)
  {
    debug_->stop();
  }
  board_->stop();
  action_.shutdown();
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
  const std::shared_ptr<ethernut::Client> client = board_->latest();
  if (!client)
  {
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "not connected yet");
    return;
  }
  const ethernut::ClientStats st = client->stats();      // round trips: this connection
  const ethernut::ClientStats total = board_->totals();  // counters: since the node started
  status.summary(diagnostic_msgs::DiagnosticStatus::OK, ethernut::toString(client->state()));
  if (st.last_board_error != 0.0f)
  {
    status.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN, "the board reported an error code");
  }
  status.add("session state", ethernut::toString(client->state()));
  status.add("board mode", ethernut::toString(client->mode()));
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
  status.add("reconnects", board_->reconnects());
  kill_->addTo(status);
  motion_->addTo(status);
}

// ------------------------------------------------------------------------------ the debug channel
// ~debug_port: every line the board prints on its debug port, on `debug`, and in diagnostics.
void EthernutNode::startDebugChannel()
{
  if (!settings_.debug)
  {
    return;
  }
  debug_pub_ = nh_.advertise<std_msgs::String>("debug", 100);
  debug_ = std::make_unique<ethernut::DebugChannel>(*settings_.debug);
  state_->diagnostics().add("ethernut debug channel", this, &EthernutNode::debugDiagnostics);
  debug_->start(
      [this](const ethernut::DebugLine& line)
      {
        std_msgs::String message;
        message.data = line.display();
        debug_pub_.publish(message);
      });
}

void EthernutNode::debugDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  const ethernut::DebugChannelStatus st = debug_->status();
  if (st.link == LinkState::kUp)
  {
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "reading " + st.device);
  }
  else
  {
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN,
                   std::string("debug port ") + toString(st.link) + (st.why.empty() ? "" : ": " + st.why));
  }
  // Mostly escaped bytes: the line settings do not match the board's (a 7-bit or slower line).
  if (st.counts.bytes >= 32 && st.counts.escaped_bytes * 2 > st.counts.bytes)
  {
    status.mergeSummary(diagnostic_msgs::DiagnosticStatus::WARN,
                        "most bytes are not text: check " + pnh_.resolveName("debug_baud") + " and the line settings");
  }
  status.add("device", st.device);
  status.add("link", toString(st.link));
  status.add("last failure", st.why);
  status.add("lines received", st.counts.lines);
  status.add("last line", st.last_line);
  status.add("cut lines", st.counts.cut_lines);
  status.add("bytes dropped from cut lines", st.counts.dropped_bytes);
  status.add("escaped bytes", st.counts.escaped_bytes);
  status.add("unterminated lines", st.counts.unterminated);
  status.add("bytes received", st.counts.bytes);
  status.add("reconnects", st.reconnects);
}
}  // namespace cnc_bridge

// Four threads, serving from the start: services and the action may wait for the board concurrently.
int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::EthernutNode>(argc, argv, "ethernut_node", {4, true});
}
