// ethernut_node: drives an ethernut board (the qCNC opcode protocol over TCP) from ROS
// (docs/ethernut_node.md). It keeps the link up (init, mode, keepalive, reconnect), streams jobs
// from G-code files or point lists through the ~run_job action, carries pause/resume/reset/kill/mode
// requests, publishes the machine's reported and commanded position as state (the reported one as
// joint_states/tf), a preview of each job for rviz before it runs, and the lines the board prints
// on its serial debug port (~debug_port: the core ethernut::DebugChannel) on `debug`. The protocol and the jobs
// (coordinates, segments, preview, streaming: ethernut::JobStreamer, whose program steps and
// holds are the common JobRunner's) live in the ROS-free cnc_bridge_ethernut library.
// The connection (link, reconnection, the protocol loop) is the core ethernut::BoardSession.
// src/ros/nodes/ethernut_params.cpp: every parameter, into the core's settings;
// src/ros/nodes/ethernut_node.cpp: the session, preview, diagnostics;
// src/ros/nodes/ethernut_services.cpp: the client's events and the services;
// src/ros/nodes/ethernut_jobs.cpp: the ~run_job action (the streamer's calls as feedback and state).
#pragma once

#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <atomic>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "cnc_bridge/EthernutCoordinates.h"
#include "cnc_bridge/EthernutSetMode.h"
#include "cnc_bridge/RunJobAction.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/ethernut/board_session.h"
#include "cnc_bridge/ethernut/client.h"
#include "cnc_bridge/ethernut/debug_channel.h"
#include "cnc_bridge/ethernut/job.h"
#include "cnc_bridge/ethernut/job_streamer.h"
#include "cnc_bridge/ethernut/settings.h"
#include "cnc_bridge/gcode/gcode.h"
#include "cnc_bridge/ros/machine_frame.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/runtime_switch.h"
#include "cnc_bridge/ros/single_goal_action_server.h"

namespace cnc_bridge
{
namespace ethernut_params
{
/// \brief Every parameter of ethernut_node (ethernut_params.cpp), validated.
struct Settings
{
  ethernut::SessionSettings session;  ///< ~host, ~tcp_port, ~connect_timeout, the client's timeouts, ~mode
  ethernut::JobSettings jobs;         ///< ~program_dir, the G-code options, ~g53_moves, ~soft_limits, ...
  double transform_timeout = 0.5;     ///< s, ~transform_timeout
  std::string kill_enabled_by;        ///< "PROG_CNCkill|1 in <file>" when the settings file enables ~kill
  /// ~debug_port and its line settings: the board's serial debug channel; none when ~debug_port is empty.
  std::optional<ethernut::DebugChannelSettings> debug;
};

/// \brief Reads them. \throws ConfigError naming the parameter (or the settings file's line).
Settings read(const ros::NodeHandle& pnh);
}  // namespace ethernut_params

class EthernutNode : public ethernut::ClientListener
{
 public:
  // The board's unit is the millimetre (qCNC's coordinates are G-code values; our parser turns
  // inches into mm); messages are in metres.
  static constexpr double kMetresPerMm = 0.001;

  EthernutNode(ros::NodeHandle nh, ros::NodeHandle pnh);
  ~EthernutNode() override;
  EthernutNode(const EthernutNode&) = delete;
  EthernutNode& operator=(const EthernutNode&) = delete;

 private:
  class JobView;  // ethernut_jobs.cpp: a job's calls as feedback and state

  // ethernut_node.cpp: the session, preview, diagnostics.
  std::shared_ptr<ethernut::Client> client(std::string& why) { return board_->client(why); }
  void publishPreview(const ethernut::Preview& preview);
  void protocolDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status);
  void startDebugChannel();
  void debugDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status);

  // ethernut_services.cpp: the client's events (its run() thread) and the services.
  void onState(ethernut::SessionState st, ethernut::SessionState previous) override;
  void onPosition(float x, float y, float z) override;
  void onCoordinateDone(uint64_t index, const ethernut::Coordinate& c) override;
  void onResend(uint64_t index, unsigned count) override;
  void onJobFinished(ethernut::JobOutcome outcome, const std::string& message) override;
  void onBoardError(float code) override;

  template <typename Response, typename F>
  bool command(Response& res, const std::string& what, F f);
  /// Fills \p res with the refusal of \p service when motion is disabled (the caller holds
  /// the switch's gate, so the switch cannot change before the command goes out). \returns true then.
  template <typename Response>
  bool motionRefused(Response& res, const std::string& service) const;
  bool onPause(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onResume(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  void onMotionSwitched(bool enabled, const std::string& caller);
  bool onClear(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onReset(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onSyncOled(EthernutCoordinates::Request& req, EthernutCoordinates::Response& res);
  bool onBoardCommand(EthernutCoordinates::Request& req, EthernutCoordinates::Response& res);
  bool onKill(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onSetMode(EthernutSetMode::Request& req, EthernutSetMode::Response& res);

  // ethernut_jobs.cpp: the ~run_job action.
  void execute(const RunJobGoalConstPtr& goal);
  void abortGoal(RunJobResult& result, const std::string& message);
  std::shared_ptr<ethernut::Job> loadJob(const RunJobGoal& goal, std::string& program, std::string& refusal);
  std::shared_ptr<ethernut::Job> loadProgram(const RunJobGoal& goal, std::string& refusal);
  std::shared_ptr<ethernut::Job> loadPoints(const RunJobGoal& goal, std::string& refusal);
  void endGoal(const ethernut::StreamOutcome& outcome);

  ros::NodeHandle nh_;
  ros::NodeHandle pnh_;
  const ethernut_params::Settings settings_;
  std::unique_ptr<RuntimeSwitch> kill_;
  std::unique_ptr<RuntimeSwitch> motion_;
  std::unique_ptr<ProgramDirectory> program_dir_;  // ~program_dir; none: point jobs only
  std::unique_ptr<ToMachineFrame> to_machine_;

  std::unique_ptr<MachineStatePublisher> state_;
  ros::Publisher path_pub_;
  ros::Publisher markers_pub_;
  ros::ServiceServer pause_srv_, resume_srv_, clear_srv_, reset_srv_, kill_srv_, mode_srv_, sync_oled_srv_,
      board_command_srv_;
  SingleGoalActionServer<RunJobAction> action_;
  std::unique_ptr<ethernut::JobStreamer> jobs_;    // the running job: its segments, steps and holds
  std::unique_ptr<ethernut::BoardSession> board_;  // the connection; last: its events use the rest
  ros::Publisher debug_pub_;
  std::unique_ptr<ethernut::DebugChannel> debug_;  // ~debug_port: the board's debug lines; none when off
};
}  // namespace cnc_bridge
