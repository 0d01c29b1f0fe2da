// share_node: NC programs between ~program_dir and a machine's SMB share (a Haas NGC's Net Share,
// a file server the control mounts), with the same ~send_program, ~receive_program and ~transfer
// interface as dnc_node, so orchestration code does not care which wire a machine uses
// (docs/share_node.md). The work is the core's: the share (SmbProgramStore), the transfers
// (ProgramTransfers, one at a time), withdrawals and their daily timer (withdrawal.h, DailyTimer)
// and program requests (RequestServer); this file maps parameters, services, the action, topics,
// state and diagnostics onto them. A periodic check of the share keeps the link state (UP while
// the share answers, DOWN with the reason) and serves the request files.
#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <future>
#include <memory>
#include <thread>

#include "cnc_bridge/ComparePrograms.h"
#include "cnc_bridge/DprntLine.h"
#include "cnc_bridge/FanOutProgram.h"
#include "cnc_bridge/ListPrograms.h"
#include "cnc_bridge/ProgramHistory.h"
#include "cnc_bridge/ProgramRequestEvent.h"
#include "cnc_bridge/ReceiveProgram.h"
#include "cnc_bridge/RemoveProgram.h"
#include "cnc_bridge/SendProgram.h"
#include "cnc_bridge/TransferAction.h"
#include "cnc_bridge/WithdrawProgram.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/program_dir.h"
#include "cnc_bridge/programs/archive.h"
#include "cnc_bridge/programs/daily_timer.h"
#include "cnc_bridge/programs/fan_out.h"
#include "cnc_bridge/programs/program_transfers.h"
#include "cnc_bridge/programs/request_server.h"
#include "cnc_bridge/programs/withdrawal.h"
#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/ros/single_goal_action_server.h"
#include "cnc_bridge/share/smb_store.h"

namespace cnc_bridge
{
namespace
{
/// ~url (smb://[user@]host[:port]/share[/folder], or a local directory) or ~serve_dir (a local
/// folder the PC's Samba serves to the controls): exactly one. A served folder is written like a
/// local ~url; the parameter says what it is for, and is checked to be an existing folder.
std::string shareAddress(const ros::NodeHandle& pnh)
{
  const std::string url = pnh.param<std::string>("url", "");
  const std::string serve_dir = pnh.param<std::string>("serve_dir", "");
  if (url.empty() == serve_dir.empty())
    throw ConfigError("give exactly one of " + pnh.resolveName("url") + " (a machine's share) and " +
                      pnh.resolveName("serve_dir") + " (a folder the PC serves to the controls), not " +
                      (url.empty() ? "neither" : "both"));
  if (!url.empty())
    return url;
  if (serve_dir.compare(0, 6, "smb://") == 0)
    throw ConfigError(pnh.resolveName("serve_dir") + " is a local folder the PC's Samba serves, not " + serve_dir +
                      ": give a machine's share as ~url");
  if (!std::filesystem::is_directory(serve_dir))
    throw ConfigError(pnh.resolveName("serve_dir") + " " + serve_dir +
                      " is not a folder: create it and serve it with Samba (config/share/served_share.smb.conf)");
  return serve_dir;
}
}  // namespace

class ShareNode
{
 public:
  ShareNode(ros::NodeHandle nh, ros::NodeHandle pnh);

 private:
  TransferResult run(const TransferGoal& goal, const programs::StoreProgress& progress);
  void execute(const TransferGoalConstPtr& goal);
  bool onSend(SendProgram::Request& request, SendProgram::Response& response);
  bool onReceive(ReceiveProgram::Request& request, ReceiveProgram::Response& response);
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
  void publishRequest(const programs::RequestOutcome& outcome);
  void checkShare(const ros::WallTimerEvent& event);
  void linkResult(const std::string& error);
  void diagnostics(diagnostic_updater::DiagnosticStatusWrapper& status);

  std::unique_ptr<programs::ProgramStore> store_;
  std::unique_ptr<programs::RequestServer> requests_;
  std::unique_ptr<ProgramDirectory> programs_;
  std::unique_ptr<programs::NamePattern> pattern_;
  std::unique_ptr<programs::ProtectedRange> protected_;
  std::unique_ptr<programs::ProgramArchive> archive_;
  std::unique_ptr<programs::ProgramTransfers> transfers_;
  std::string machine_;
  bool enable_remove_ = false;
  ros::Duration feedback_period_;
  std::unique_ptr<MachineStatePublisher> state_;
  ros::NodeHandle nh_;
  ros::WallDuration publish_timeout_;
  std::atomic<std::time_t> next_withdrawal_{0};
  ros::Publisher withdrawals_pub_;
  ros::ServiceServer withdraw_all_srv_;

  std::unique_ptr<SingleGoalActionServer<TransferAction>> action_;
  ros::ServiceServer send_srv_, receive_srv_, list_srv_, remove_srv_, history_srv_, compare_srv_, withdraw_srv_,
      publish_srv_;
  ros::WallTimer check_timer_;
  ros::Publisher requests_pub_;
  ros::Subscriber dprnt_sub_;
  /// ~withdraw_at; last, so that its thread stops before what it uses goes.
  std::unique_ptr<programs::DailyTimer> withdraw_timer_;
};

ShareNode::ShareNode(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh)
{
  const std::string url = shareAddress(pnh);
  // ~credentials_file (string, default "": guest): smbclient authentication file, mode 0600.
  // ~timeout (s, default 10): limit of every SMB request.
  store_ = share::openStore(url, pnh.param<std::string>("credentials_file", ""), params::seconds(pnh, "timeout", 10.0));
  // ~program_dir (string, required): the local folder programs are sent from and received into;
  // created if missing.
  const std::string program_dir = params::required<std::string>(pnh, "program_dir");
  std::error_code ignored;
  std::filesystem::create_directories(program_dir, ignored);
  programs_ = std::make_unique<ProgramDirectory>(program_dir);
  // ~name_pattern (string, default "O%05d.nc"): how the control names program files.
  pattern_ = std::make_unique<programs::NamePattern>(pnh.param<std::string>("name_pattern", "O%05d.nc"));
  // ~protected_programs (default "O08000-O09999", "none"), ~allow_protected_programs (default
  // false): as dnc_node's.
  protected_ = std::make_unique<programs::ProtectedRange>(pnh.param<std::string>("protected_programs", "O08000-O09999"),
                                                          pnh.param("allow_protected_programs", false),
                                                          "~allow_protected_programs");
  // ~archive_dir (string, default <program_dir>.archive): every program sent or received is kept
  // there, one folder per program; ~archive_keep (int, default 20) versions each.
  std::string root = programs_->root();
  archive_ =
      std::make_unique<programs::ProgramArchive>(pnh.param<std::string>("archive_dir", root + ".archive"),
                                                 static_cast<unsigned>(std::max(1, pnh.param("archive_keep", 20))));
  machine_ = pnh.param<std::string>("machine", ros::this_node::getName());
  transfers_ = std::make_unique<programs::ProgramTransfers>(*store_, *programs_, *protected_, *pattern_, *archive_,
                                                            programs::VersionSource{"share_node", machine_, ""});
  // ~request_load_words (string, default "LOAD SEND"), ~request_save_words (string, default
  // "SAVE"): the words that make a comment or DPRNT line a request, as dnc_node's.
  requests_ = std::make_unique<programs::RequestServer>(
      programs::RequestWords::parse(pnh.param<std::string>("request_load_words", "LOAD SEND"),
                                    pnh.param<std::string>("request_save_words", "SAVE"),
                                    pnh.resolveName("request_load_words"), pnh.resolveName("request_save_words")),
      *pattern_, *protected_, programs_->root(),
      [this](programs::RequestDecision::Action action, const std::string& program)
      { return requestTransfer(action, program); },
      [this](const programs::RequestOutcome& outcome) { publishRequest(outcome); });
  // ~requests_folder (string, default "requests"; "" for none): a folder of the share where the
  // control drops request files ((LOAD O1234), (SEND O1234), (SAVE O1234)), served at each check.
  const std::string requests_folder = pnh.param<std::string>("requests_folder", "requests");
  if (!requests_folder.empty())
  {
    programs::checkName(requests_folder);
    requests_->setRequestFolder(requests_folder,
                                [url, requests_folder, credentials = pnh.param<std::string>("credentials_file", ""),
                                 timeout = params::seconds(pnh, "timeout", 10.0)]
                                { return share::openStore(url + "/" + requests_folder, credentials, timeout); });
  }
  requests_pub_ = nh.advertise<ProgramRequestEvent>("program_requests", 20);
  // ~dprnt_requests (bool, default true): a DPRNT line `LOAD O1234` on dprnt/raw (dprnt_node in
  // the same machine namespace) is a request too.
  if (pnh.param("dprnt_requests", true))
    dprnt_sub_ = nh.subscribe<DprntLine>(
        "dprnt/raw", 20, [this](const DprntLine::ConstPtr& line) { requests_->serveDprntLine(line->text); });
  // ~enable_remove (bool, default false): ~remove_program deletes from the share only when set.
  pnh.param("enable_remove", enable_remove_, false);
  // ~feedback_rate (Hz, default 20): action feedback at most this often.
  feedback_period_ = ros::Duration(1.0 / params::positive(pnh, "feedback_rate", 20.0));

  state_ = std::make_unique<MachineStatePublisher>(nh, pnh, store_->describe());
  state_->update(
      [](MachineState& s)
      {
        s.mode = MachineState::MODE_DNC;
        s.execution = MachineState::EXECUTION_READY;
      });
  state_->setLink(LinkState::kConnecting, "first check of " + store_->describe());
  state_->diagnostics().add("Share", this, &ShareNode::diagnostics);

  action_ = std::make_unique<SingleGoalActionServer<TransferAction>>(
      pnh, "transfer", [this](const TransferGoalConstPtr& goal) { execute(goal); },
      [](const TransferGoal& goal) { return goal.direction + " " + goal.file; });
  action_->setCancelCallback([this] { transfers_->cancel(); });
  action_->start();
  send_srv_ = pnh.advertiseService("send_program", &ShareNode::onSend, this);
  receive_srv_ = pnh.advertiseService("receive_program", &ShareNode::onReceive, this);
  list_srv_ = pnh.advertiseService("list_programs", &ShareNode::onList, this);
  remove_srv_ = pnh.advertiseService("remove_program", &ShareNode::onRemove, this);
  history_srv_ = pnh.advertiseService("program_history", &ShareNode::onHistory, this);
  compare_srv_ = pnh.advertiseService("compare_programs", &ShareNode::onCompare, this);
  withdraw_srv_ = pnh.advertiseService("withdraw_program", &ShareNode::onWithdraw, this);
  // ~publish_timeout (s, default 60): how long ~publish_to_machines waits for each machine's
  // ~send_program to answer.
  publish_timeout_ = ros::WallDuration(params::positive(pnh, "publish_timeout", 60.0));
  publish_srv_ = pnh.advertiseService("publish_to_machines", &ShareNode::onPublishToMachines, this);
  // ~withdraw_at (string "HH:MM", local time, default "": never): every day at that time every
  // program in the share is withdrawn (kept in the archive, then removed); ~withdraw_all does it
  // on request.
  withdrawals_pub_ = nh.advertise<ProgramRequestEvent>("withdrawals", 50);
  withdraw_all_srv_ = pnh.advertiseService("withdraw_all", &ShareNode::onWithdrawAll, this);
  XmlRpc::XmlRpcValue withdraw_at;
  if (pnh.getParam("withdraw_at", withdraw_at) && withdraw_at.getType() != XmlRpc::XmlRpcValue::TypeString)
    throw ConfigError(pnh.resolveName("withdraw_at") + " must be a string \"HH:MM\": quote it in YAML ('18:00'), " +
                      "which otherwise reads 18:00 as a number");
  if (const auto at =
          programs::DailyTime::parse(pnh.param<std::string>("withdraw_at", ""), pnh.resolveName("withdraw_at")))
    withdraw_timer_ = std::make_unique<programs::DailyTimer>(
        *at, [this, source = "~withdraw_at " + at->str()] { withdrawAll(source); },
        [this](std::time_t next) { onWithdrawalScheduled(next); });
  // ~check_period (s, default 5): how often the share is listed to keep the link state.
  check_timer_ =
      nh.createWallTimer(ros::WallDuration(params::positive(pnh, "check_period", 5.0)), &ShareNode::checkShare, this);
  checkShare(ros::WallTimerEvent());
  ROS_INFO("share_node on %s, programs in %s", store_->describe().c_str(), programs_->root().c_str());
}

void ShareNode::linkResult(const std::string& error)
{
  // Only a change is set: the state's message otherwise keeps the last transfer's result.
  const MachineState now = state_->snapshot();
  if (error.empty() && now.link != MachineState::LINK_UP)
    state_->setLink(LinkState::kUp, "share answers");
  else if (!error.empty() && (now.link != MachineState::LINK_DOWN || now.message != error))
    state_->setLink(LinkState::kDown, error);
}

void ShareNode::checkShare(const ros::WallTimerEvent&)
{
  if (transfers_->busy())
    return;  // a running transfer says whether the share answers
  const auto start = std::chrono::steady_clock::now();
  std::string error;
  try
  {
    store_->list();
  }
  catch (const Error& e)
  {
    error = e.what();
  }
  if (transfers_->countCheck(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), error))
    ROS_ERROR("%s", error.c_str());
  linkResult(error);
  if (error.empty())
    requests_->serveRequestFiles();
}

programs::RequestTransfer ShareNode::requestTransfer(programs::RequestDecision::Action action,
                                                     const std::string& program)
{
  TransferGoal goal;
  goal.file = program;
  goal.direction = action == programs::RequestDecision::Action::kSend ? TransferGoal::DIRECTION_SEND
                                                                      : TransferGoal::DIRECTION_RECEIVE;
  const TransferResult result = run(goal, nullptr);
  return {static_cast<bool>(result.success), result.message};
}

void ShareNode::publishRequest(const programs::RequestOutcome& outcome)
{
  ProgramRequestEvent event;
  event.header.stamp = ros::Time::now();
  event.machine = machine_;
  event.source = outcome.source;
  event.request = outcome.word;
  event.number = outcome.number;
  event.program = outcome.program;
  event.success = outcome.success;
  event.outcome = outcome.outcome;
  requests_pub_.publish(event);
}

TransferResult ShareNode::run(const TransferGoal& goal, const programs::StoreProgress& progress)
{
  TransferResult result;
  const bool send = goal.direction == TransferGoal::DIRECTION_SEND;
  if (!send && goal.direction != TransferGoal::DIRECTION_RECEIVE)
  {
    result.message = "refused: direction must be 'send' or 'receive', not '" + goal.direction + "'";
    return result;
  }
  if (!goal.protocol.empty() && goal.protocol != "smb")
  {
    result.message =
        "refused: share_node moves whole files over SMB (protocol '' or 'smb'), not '" + goal.protocol + "'";
    return result;
  }
  bool started = false;
  const programs::TransferOutcome outcome = transfers_->run(
      send ? programs::ProgramTransfers::Direction::kSend : programs::ProgramTransfers::Direction::kReceive, goal.file,
      progress,
      [&]
      {
        started = true;
        state_->update(
            [&](MachineState& s)
            {
              s.execution = MachineState::EXECUTION_ACTIVE;
              s.program = goal.file;
              s.message = (send ? "sending " : "receiving ") + goal.file;
            });
      });
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
  ros::Time last;
  const TransferResult result = run(*goal,
                                    [&](uint64_t done, uint64_t total)
                                    {
                                      const ros::Time now = ros::Time::now();
                                      if (done < total && now - last < feedback_period_)
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

bool ShareNode::onSend(SendProgram::Request& request, SendProgram::Response& response)
{
  TransferGoal goal;
  goal.direction = TransferGoal::DIRECTION_SEND;
  goal.file = request.file;
  goal.protocol = request.protocol;
  const TransferResult result = run(goal, nullptr);
  response.success = result.success;
  response.message = result.message;
  response.bytes = result.bytes;
  return true;
}

bool ShareNode::onReceive(ReceiveProgram::Request& request, ReceiveProgram::Response& response)
{
  TransferGoal goal;
  goal.direction = TransferGoal::DIRECTION_RECEIVE;
  goal.file = request.file;
  goal.protocol = request.protocol;
  const TransferResult result = run(goal, nullptr);
  response.success = result.success;
  response.message = result.message;
  response.bytes = result.bytes;
  return true;
}

bool ShareNode::onList(ListPrograms::Request&, ListPrograms::Response& response)
{
  try
  {
    for (const programs::ProgramListing& item : programs::listPrograms(*store_, *pattern_))
    {
      ProgramInfo info;
      info.name = item.entry.name;
      const auto number = item.header.number ? item.header.number : item.name_number;
      info.number = number ? static_cast<int32_t>(*number) : -1;
      info.size = item.entry.size;
      info.mtime = ros::Time(static_cast<uint32_t>(std::max<int64_t>(0, item.entry.mtime)), 0);
      info.comment = item.header.comment;
      response.programs.push_back(info);
    }
    response.success = true;
    response.message = std::to_string(response.programs.size()) + " programs on " + store_->describe();
  }
  catch (const Error& e)
  {
    response.message = e.what();
    if (dynamic_cast<const LinkError*>(&e) != nullptr)
      linkResult(e.what());
  }
  return true;
}

bool ShareNode::onRemove(RemoveProgram::Request& request, RemoveProgram::Response& response)
{
  if (!enable_remove_)
  {
    response.message = "refused: removing programs from " + store_->describe() + " is off (set ~enable_remove)";
    return true;
  }
  try
  {
    store_->remove(request.file);
    response.success = true;
    response.message = "removed " + request.file + " from " + store_->describe();
    ROS_INFO("%s", response.message.c_str());
  }
  catch (const Error& e)
  {
    response.message = e.what();
  }
  return true;
}

bool ShareNode::onWithdraw(WithdrawProgram::Request& request, WithdrawProgram::Response& response)
{
  try
  {
    const programs::Withdrawal done =
        programs::withdrawProgram(*store_, *archive_, request.file, {"share_node", machine_, "withdrawn"});
    response.success = done.success;
    response.message = done.message;
    response.version = done.version;
  }
  catch (const Error& e)
  {
    response.message = e.what();
  }
  return true;
}

programs::WithdrawalSummary ShareNode::withdrawAll(const std::string& source)
{
  return programs::withdrawAllPrograms(*store_, *archive_, {"share_node", machine_, "withdrawn"}, source,
                                       [&](const programs::Withdrawal& outcome)
                                       {
                                         ProgramRequestEvent event;
                                         event.header.stamp = ros::Time::now();
                                         event.machine = machine_;
                                         event.source = source;
                                         event.request = "WITHDRAW";
                                         event.program = outcome.program;
                                         event.success = outcome.success;
                                         event.outcome = outcome.message;
                                         withdrawals_pub_.publish(event);
                                       });
}

bool ShareNode::onWithdrawAll(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response)
{
  const programs::WithdrawalSummary summary = withdrawAll("~withdraw_all");
  response.success = summary.success;
  response.message = summary.message;
  return true;
}

void ShareNode::onWithdrawalScheduled(std::time_t next)
{
  next_withdrawal_ = next;
  char when[32];
  std::tm local{};
  ::localtime_r(&next, &local);
  std::strftime(when, sizeof when, "%Y-%m-%d %H:%M %Z", &local);
  ROS_INFO("next withdrawal of every program from %s: %s", store_->describe().c_str(), when);
}

bool ShareNode::onHistory(ProgramHistory::Request& request, ProgramHistory::Response& response)
{
  try
  {
    for (const programs::ArchiveVersion& v : archive_->history(request.file))
    {
      ProgramVersion version;
      version.number = v.number;
      version.stamp = ros::Time(static_cast<uint32_t>(std::max<int64_t>(0, v.time)), 0);
      version.node = v.source.node;
      version.machine = v.source.machine;
      version.direction = v.source.direction;
      version.size = v.size;
      version.crc32 = v.crc32;
      response.versions.push_back(version);
    }
    response.success = true;
    response.message =
        std::to_string(response.versions.size()) + " versions of " + request.file + " in " + archive_->root();
  }
  catch (const Error& e)
  {
    response.message = e.what();
  }
  return true;
}

bool ShareNode::onCompare(ComparePrograms::Request& request, ComparePrograms::Response& response)
{
  try
  {
    const std::string current = programs_->root() + "/" + request.file.substr(request.file.find_last_of('/') + 1);
    response.diff = programs::compareVersions(*archive_, request.file, request.from, request.to, current);
    response.success = true;
    response.message = response.diff.empty() ? "identical" : "different";
  }
  catch (const Error& e)
  {
    response.message = e.what();
  }
  return true;
}

std::string ShareNode::sendThrough(const std::string& machine, const std::string& file)
{
  // A share_node's name, or the namespace a share_node runs in.
  std::string service = nh_.resolveName(machine) + "/send_program";
  if (!ros::service::exists(service, false))
  {
    const std::string in_namespace = nh_.resolveName(machine) + "/share_node/send_program";
    if (!ros::service::exists(in_namespace, false))
      throw LinkError("no machine answers at " + service + " nor " + in_namespace +
                      ": is its share_node running, and is the name right?");
    service = in_namespace;
  }
  // roscpp service calls have no timeout: the call runs on a thread of its own, which a machine
  // that never answers leaves behind until its connection closes.
  auto answer = std::make_shared<std::promise<std::optional<SendProgram::Response>>>();
  std::future<std::optional<SendProgram::Response>> result = answer->get_future();
  std::thread(
      [service, file, answer]
      {
        SendProgram call;
        call.request.file = file;
        if (ros::service::call(service, call))
          answer->set_value(call.response);
        else
          answer->set_value(std::nullopt);
      })
      .detach();
  if (result.wait_for(std::chrono::duration<double>(publish_timeout_.toSec())) != std::future_status::ready)
  {
    char seconds[32];
    std::snprintf(seconds, sizeof seconds, "%g", publish_timeout_.toSec());
    throw TimeoutError("no answer from " + service + " within " + seconds +
                       " s (~publish_timeout); the send may still finish there");
  }
  const std::optional<SendProgram::Response> response = result.get();
  if (!response)
    throw LinkError("the call of " + service + " failed: its share_node stopped or refused the connection");
  if (!response->success)
    throw Error(response->message);
  return response->message;
}

bool ShareNode::onPublishToMachines(FanOutProgram::Request& request, FanOutProgram::Response& response)
{
  std::vector<std::string> failed;
  const auto results = programs::fanOut(
      request.machines, [&](const std::string& machine) { return sendThrough(machine, request.file); },
      [&](const programs::TargetResult& result)
      {
        response.machines.push_back(result.target);
        response.succeeded.push_back(result.success);
        response.messages.push_back(result.message);
        if (result.success)
        {
          ROS_INFO("publish %s to %s: %s", request.file.c_str(), result.target.c_str(), result.message.c_str());
        }
        else
        {
          failed.push_back(result.target + " (" + result.message + ")");
          ROS_ERROR("publish %s to %s failed: %s", request.file.c_str(), result.target.c_str(), result.message.c_str());
        }
      });
  response.success = programs::allSucceeded(results);
  response.message = std::to_string(results.size() - failed.size()) + " of " + std::to_string(results.size()) +
                     " machines got " + request.file;
  for (size_t i = 0; i < failed.size(); ++i)
    response.message += (i == 0 ? "; failed: " : ", ") + failed[i];
  if (results.empty())
    response.message = "no machines given: nothing published";
  return true;
}

void ShareNode::diagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  const programs::TransferCounts counts = transfers_->counts();
  if (counts.failed > 0 && counts.last_result == counts.last_error)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "last transfer failed: " + counts.last_error);
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK,
                   counts.last_result.empty() ? "no transfer yet" : counts.last_result);
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
