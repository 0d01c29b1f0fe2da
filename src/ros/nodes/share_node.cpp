// share_node (src/ros/nodes/share_node.h): the core objects built from the settings
// (src/ros/nodes/share_params.cpp); the transfers (the action, ~send_program, ~receive_program and
// program requests), the periodic check of the share, state and diagnostics. The other services:
// src/ros/nodes/share_services.cpp.
#include "share_node.h"

#include <filesystem>

#include "cnc_bridge/DprntLine.h"
#include "cnc_bridge/ReceiveProgram.h"
#include "cnc_bridge/SendProgram.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/request_boundary.h"
#include "cnc_bridge/share/share_service.h"
#include "cnc_bridge/share/smb_store.h"

namespace cnc_bridge
{
namespace
{
/// The shown link of a machine state, as the core's LinkState.
LinkState shownLink(const MachineState& state)
{
  if (state.link == MachineState::LINK_UP)
    return LinkState::kUp;
  return state.link == MachineState::LINK_DOWN ? LinkState::kDown : LinkState::kConnecting;
}
}  // namespace

ShareNode::ShareNode(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh)
{
  const share::StoreSettings store = readStoreSettings(pnh);
  store_ = share::openStore(store.address, store.credentials_file, store.timeout);
  program_settings_ = readProgramSettings(pnh);
  std::error_code ignored;
  std::filesystem::create_directories(program_settings_.program_dir, ignored);
  programs_ = std::make_unique<ProgramDirectory>(program_settings_.program_dir);
  archive_ = std::make_unique<programs::ProgramArchive>(
      share::archiveDir(program_settings_.archive_dir, programs_->root()), program_settings_.archive_keep);
  transfers_ = std::make_unique<programs::ProgramTransfers>(
      *store_, *programs_, program_settings_.protected_range, program_settings_.pattern, *archive_,
      programs::VersionSource{"share_node", program_settings_.machine, ""});
  startRequests(nh, store, readRequestSettings(pnh));
  settings_ = readNodeSettings(pnh);

  state_ = std::make_unique<MachineStatePublisher>(nh, pnh, store_->describe());
  state_->update(
      [](MachineState& s)
      {
        s.mode = MachineState::MODE_DNC;
        s.execution = MachineState::EXECUTION_READY;
      });
  state_->setLink(LinkState::kConnecting, "first check of " + store_->describe());
  state_->diagnostics().add("Share", this, &ShareNode::diagnostics);
  hub_ = startShareHub(nh, store, readHubSettings(pnh), program_settings_, *archive_, *state_);
  withdrawals_pub_ = nh.advertise<ProgramRequestEvent>("withdrawals", 50);
  advertise(pnh);
  if (const auto at = settings_.withdraw_at)
    withdraw_timer_ = std::make_unique<programs::DailyTimer>(
        *at, [this, source = "~withdraw_at " + at->str()] { withdrawAll(source); },
        [this](std::time_t next) { onWithdrawalScheduled(next); });
  check_timer_ = nh.createWallTimer(ros::WallDuration(settings_.check_period), &ShareNode::checkShare, this);
  checkShare(ros::WallTimerEvent());
  ROS_INFO("share_node on %s, programs in %s", store_->describe().c_str(), programs_->root().c_str());
}

void ShareNode::startRequests(ros::NodeHandle& nh, const share::StoreSettings& store,
                              const share::RequestSettings& settings)
{
  requests_ = std::make_unique<programs::RequestServer>(
      settings.words, program_settings_.pattern, program_settings_.protected_range, programs_->root(),
      [this](programs::RequestDecision::Action action, const std::string& program)
      { return requestTransfer(action, program); },
      [this](const programs::RequestOutcome& outcome) { publishRequest(outcome); });
  if (!settings.folder.empty())
    requests_->setRequestFolder(settings.folder,
                                [store, address = share::requestsAddress(store.address, settings.folder)]
                                { return share::openStore(address, store.credentials_file, store.timeout); });
  requests_pub_ = nh.advertise<ProgramRequestEvent>("program_requests", 20);
  if (settings.dprnt)
    dprnt_sub_ = nh.subscribe<DprntLine>(
        "dprnt/raw", 20, [this](const DprntLine::ConstPtr& line) { requests_->serveDprntLine(line->text); });
}

template <class Service>
ros::ServiceServer ShareNode::advertiseTransfer(ros::NodeHandle& pnh, const std::string& name,
                                                const std::string& direction)
{
  return advertiseGuardedService<Service>(
      pnh, name,
      [this, direction](typename Service::Request& request, typename Service::Response& response)
      {
        const TransferResult result = run(direction, request.protocol, request.file, nullptr);
        response.success = result.success;
        response.message = result.message;
        response.bytes = result.bytes;
        return true;
      });
}

void ShareNode::advertise(ros::NodeHandle& pnh)
{
  action_ = std::make_unique<SingleGoalActionServer<TransferAction>>(
      pnh, "transfer", [this](const TransferGoalConstPtr& goal) { execute(goal); },
      [](const TransferGoal& goal) { return goal.direction + " " + goal.file; });
  action_->setCancelCallback([this] { transfers_->cancel(); });
  action_->start();
  send_srv_ = advertiseTransfer<SendProgram>(pnh, "send_program", TransferGoal::DIRECTION_SEND);
  receive_srv_ = advertiseTransfer<ReceiveProgram>(pnh, "receive_program", TransferGoal::DIRECTION_RECEIVE);
  list_srv_ = advertiseGuardedService(pnh, "list_programs", &ShareNode::onList, this);
  remove_srv_ = advertiseGuardedService(pnh, "remove_program", &ShareNode::onRemove, this);
  history_srv_ = advertiseGuardedService(pnh, "program_history", &ShareNode::onHistory, this);
  compare_srv_ = advertiseGuardedService(pnh, "compare_programs", &ShareNode::onCompare, this);
  withdraw_srv_ = advertiseGuardedService(pnh, "withdraw_program", &ShareNode::onWithdraw, this);
  publish_srv_ = advertiseGuardedService(pnh, "publish_to_machines", &ShareNode::onPublishToMachines, this);
  withdraw_all_srv_ = advertiseGuardedService(pnh, "withdraw_all", &ShareNode::onWithdrawAll, this);
}

void ShareNode::linkResult(const std::string& error)
{
  const MachineState now = state_->snapshot();
  if (const auto change = share::linkChange(shownLink(now), now.message, error))
    state_->setLink(change->state, change->message);
}

void ShareNode::checkShare(const ros::WallTimerEvent&)
{
  const share::StoreCheck check = share::checkStore(*store_, *transfers_);
  if (!check.checked)
    return;
  if (check.new_error)
    ROS_ERROR("%s", check.error.c_str());
  linkResult(check.error);
  if (check.error.empty())
    requests_->serveRequestFiles();
}

programs::RequestTransfer ShareNode::requestTransfer(programs::RequestDecision::Action action,
                                                     const std::string& program)
{
  const TransferResult result =
      transfer(action == programs::RequestDecision::Action::kSend ? programs::ProgramTransfers::Direction::kSend
                                                                  : programs::ProgramTransfers::Direction::kReceive,
               program, nullptr);
  return {static_cast<bool>(result.success), result.message};
}

ProgramRequestEvent ShareNode::event(const std::string& source, const std::string& request, const std::string& program,
                                     bool success, const std::string& outcome) const
{
  ProgramRequestEvent event;
  event.header.stamp = ros::Time::now();
  event.machine = program_settings_.machine;
  event.source = source;
  event.request = request;
  event.program = program;
  event.success = success;
  event.outcome = outcome;
  return event;
}

void ShareNode::publishRequest(const programs::RequestOutcome& outcome)
{
  ProgramRequestEvent request = event(outcome.source, outcome.word, outcome.program, outcome.success, outcome.outcome);
  request.number = outcome.number;
  requests_pub_.publish(request);
}

TransferResult ShareNode::run(const std::string& direction, const std::string& protocol, const std::string& file,
                              const programs::StoreProgress& progress)
{
  const share::TransferRequest request = share::transferRequest(direction, protocol);
  if (request.direction)
    return transfer(*request.direction, file, progress);
  TransferResult refused;
  refused.message = request.refusal;
  return refused;
}

TransferResult ShareNode::transfer(programs::ProgramTransfers::Direction direction, const std::string& file,
                                   const programs::StoreProgress& progress)
{
  const bool send = direction == programs::ProgramTransfers::Direction::kSend;
  bool started = false;
  const auto show_started = [&]
  {
    started = true;
    state_->update(
        [&](MachineState& s)
        {
          s.execution = MachineState::EXECUTION_ACTIVE;
          s.program = file;
          s.message = (send ? "sending " : "receiving ") + file;
        });
  };
  const programs::TransferOutcome outcome = transfers_->run(direction, file, progress, show_started);
  TransferResult result;
  result.success = outcome.success;
  result.message = outcome.message;
  result.bytes = outcome.bytes;
  if (!started)
    return result;  // refused: another transfer runs, and the state is its
  if (outcome.success || outcome.link_lost)
    linkResult(outcome.success ? "" : outcome.message);
  state_->update(
      [&](MachineState& s)
      {
        s.execution = result.success ? MachineState::EXECUTION_READY : MachineState::EXECUTION_STOPPED;
        s.message = result.message;
      });
  return result;
}

void ShareNode::execute(const TransferGoalConstPtr& goal)
{
  const ros::Duration feedback_period(1.0 / settings_.feedback_rate);
  ros::Time last;
  const TransferResult result = run(goal->direction, goal->protocol, goal->file,
                                    [&](uint64_t done, uint64_t total)
                                    {
                                      const ros::Time now = ros::Time::now();
                                      if (done < total && now - last < feedback_period)
                                        return;
                                      last = now;
                                      TransferFeedback feedback;
                                      feedback.bytes = done;
                                      feedback.total = total;
                                      feedback.percent = total > 0 ? static_cast<float>(100.0 * done / total) : 0.0f;
                                      action_->publishFeedback(feedback);
                                    });
  if (result.success)
    action_->setSucceeded(result, result.message);
  else if (transfers_->cancelled())
    action_->setPreempted(result, result.message);
  else
    action_->setAborted(result, result.message);
}

void ShareNode::onWithdrawalScheduled(std::time_t next)
{
  next_withdrawal_ = next;
  ROS_INFO("next withdrawal of every program from %s: %s", store_->describe().c_str(),
           share::localTimeText(next).c_str());
}

void ShareNode::diagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  const programs::TransferCounts counts = transfers_->counts();
  const share::TransfersSummary summary = share::transfersSummary(counts);
  status.summary(summary.warn ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK,
                 summary.text);
  status.add("share", store_->describe());
  status.add("program_dir", programs_->root());
  status.add("transfers", counts.transfers);
  status.add("completed", counts.completed);
  status.add("failed", counts.failed);
  status.add("refused", counts.refused);
  status.add("bytes", counts.bytes);
  status.add("checks", counts.checks);
  status.add("check failures", counts.check_failures);
  status.add("round trip (s)", counts.round_trip);
  status.add("last error", counts.last_error);
  if (withdraw_timer_)
    status.add("next withdrawal (unix time)", static_cast<int64_t>(next_withdrawal_.load()));
}
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  // Several threads: a service call may run a whole transfer, and the share is checked meanwhile.
  return cnc_bridge::runNode<cnc_bridge::ShareNode>(argc, argv, "share_node", cnc_bridge::Spinning{4});
}
