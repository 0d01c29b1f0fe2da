// share_node: NC programs between ~program_dir and a machine's SMB share (a Haas NGC's Net Share,
// a file server the control mounts), with the same ~send_program, ~receive_program and ~transfer
// interface as dnc_node, so orchestration code does not care which wire a machine uses
// (docs/share_node.md). The work is the core's: the share (SmbProgramStore), the transfers
// (ProgramTransfers, one at a time), withdrawals and their daily timer (withdrawal.h, DailyTimer),
// program requests (RequestServer), and what the services decide (share_service.h). A periodic
// check of the share keeps the link state (UP while the share answers, DOWN with the reason) and
// serves the request files. src/ros/nodes/share_params.cpp: the parameters, as the core's settings;
// src/ros/nodes/share_node.cpp: the core objects, the transfers, the check, state and diagnostics;
// src/ros/nodes/share_services.cpp: the other services.
#pragma once

#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <atomic>
#include <ctime>
#include <memory>
#include <string>

#include "cnc_bridge/ComparePrograms.h"
#include "cnc_bridge/FanOutProgram.h"
#include "cnc_bridge/ListPrograms.h"
#include "cnc_bridge/ProgramHistory.h"
#include "cnc_bridge/ProgramRequestEvent.h"
#include "cnc_bridge/RemoveProgram.h"
#include "cnc_bridge/TransferAction.h"
#include "cnc_bridge/WithdrawProgram.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/daily_timer.h"
#include "cnc_bridge/programs/program_transfers.h"
#include "cnc_bridge/programs/request_server.h"
#include "cnc_bridge/programs/withdrawal.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/single_goal_action_server.h"
#include "cnc_bridge/share/share_settings.h"

namespace cnc_bridge
{
// share_params.cpp: each part of the node's parameters (docs/share_node.md), checked, as the
// core's settings. \throws ConfigError naming the parameter.
share::StoreSettings readStoreSettings(const ros::NodeHandle& pnh);
share::ProgramSettings readProgramSettings(const ros::NodeHandle& pnh);
share::RequestSettings readRequestSettings(const ros::NodeHandle& pnh);
share::NodeSettings readNodeSettings(const ros::NodeHandle& pnh);
share::HubSettings readHubSettings(const ros::NodeHandle& pnh);

/// \brief The hybrid share (share_hub.cpp): the drop folder and the collection polled on a timer of
/// their own, each result published on hub_events, logged, kept in <archive>/hub_results.log and
/// counted in the diagnostics.
class ShareHub;
/// \returns the running hub, or none when neither ~drop_to nor ~collect_from is set.
/// \throws ConfigError for a machine share that cannot be opened.
std::shared_ptr<ShareHub> startShareHub(ros::NodeHandle nh, const share::StoreSettings& store,
                                        const share::HubSettings& hub, const share::ProgramSettings& programs,
                                        programs::ProgramArchive& archive, MachineStatePublisher& state);

class ShareNode
{
 public:
  ShareNode(ros::NodeHandle nh, ros::NodeHandle pnh);

 private:
  void startRequests(ros::NodeHandle& nh, const share::StoreSettings& store, const share::RequestSettings& settings);
  void advertise(ros::NodeHandle& pnh);
  /// A transfer asked for by name (the action, ~send_program, ~receive_program): refused unless
  /// the direction and protocol are share_node's, else transfer().
  TransferResult run(const std::string& direction, const std::string& protocol, const std::string& file,
                     const programs::StoreProgress& progress);
  /// Runs one transfer, shown in the state while it runs.
  TransferResult transfer(programs::ProgramTransfers::Direction direction, const std::string& file,
                          const programs::StoreProgress& progress);
  void execute(const TransferGoalConstPtr& goal);
  /// ~send_program and ~receive_program: the same transfer, one direction each.
  template <class Service>
  ros::ServiceServer advertiseTransfer(ros::NodeHandle& pnh, const std::string& name, const std::string& direction);
  bool onList(ListPrograms::Request& request, ListPrograms::Response& response);
  bool onRemove(RemoveProgram::Request& request, RemoveProgram::Response& response);
  bool onHistory(ProgramHistory::Request& request, ProgramHistory::Response& response);
  bool onWithdraw(WithdrawProgram::Request& request, WithdrawProgram::Response& response);
  /// Withdraws every program in the share, each outcome published on withdrawals; \returns the
  /// summary. The path of both ~withdraw_at and ~withdraw_all.
  programs::WithdrawalSummary withdrawAll(const std::string& source);
  bool onWithdrawAll(std_srvs::Trigger::Request& request, std_srvs::Trigger::Response& response);
  /// Logs the next ~withdraw_at and keeps it for the diagnostics.
  void onWithdrawalScheduled(std::time_t next);
  bool onCompare(ComparePrograms::Request& request, ComparePrograms::Response& response);
  bool onPublishToMachines(FanOutProgram::Request& request, FanOutProgram::Response& response);
  /// Calls \p machine's ~send_program with \p file; \returns its message, throws its failure.
  std::string sendThrough(const std::string& machine, const std::string& file);
  /// A request's transfer: LOAD/SEND publishes the program into the share, SAVE fetches it.
  programs::RequestTransfer requestTransfer(programs::RequestDecision::Action action, const std::string& program);
  /// An event of program_requests or withdrawals, stamped now, for this machine.
  ProgramRequestEvent event(const std::string& source, const std::string& request, const std::string& program,
                            bool success, const std::string& outcome) const;
  void publishRequest(const programs::RequestOutcome& outcome);
  void checkShare(const ros::WallTimerEvent& event);
  void linkResult(const std::string& error);
  void diagnostics(diagnostic_updater::DiagnosticStatusWrapper& status);

  ros::NodeHandle nh_;
  std::unique_ptr<programs::ProgramStore> store_;
  std::unique_ptr<ProgramDirectory> programs_;
  share::ProgramSettings program_settings_;
  std::unique_ptr<programs::ProgramArchive> archive_;
  std::unique_ptr<programs::ProgramTransfers> transfers_;
  std::unique_ptr<programs::RequestServer> requests_;
  share::NodeSettings settings_;
  std::unique_ptr<MachineStatePublisher> state_;
  std::atomic<std::time_t> next_withdrawal_{0};
  ros::Publisher withdrawals_pub_, requests_pub_;

  std::unique_ptr<SingleGoalActionServer<TransferAction>> action_;
  ros::ServiceServer send_srv_, receive_srv_, list_srv_, remove_srv_, history_srv_, compare_srv_, withdraw_srv_,
      publish_srv_, withdraw_all_srv_;
  ros::WallTimer check_timer_;
  ros::Subscriber dprnt_sub_;
  /// ~withdraw_at; last, so that its thread stops before what it uses goes.
  std::unique_ptr<programs::DailyTimer> withdraw_timer_;
  std::shared_ptr<ShareHub> hub_;
};
}  // namespace cnc_bridge
