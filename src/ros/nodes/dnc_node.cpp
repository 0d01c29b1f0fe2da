// dnc_node: NC program transfer between ~program_dir and a control's RS-232 port (see dnc_node.h
// and docs/dnc_node.md). This file holds the core objects built from the settings (the parameters
// are read in dnc_params.cpp), the serial link, state and diagnostics,
// the run of one transfer, and the XModem protocol handler; the action and services are in
// dnc_transfer_action.cpp. The rules a transfer follows (one at a time, the files it may touch,
// the archive, the counters) are the core's (cnc_bridge/programs/transfer_core.h, shared with
// share_node; cnc_bridge/dnc/transfer_rules.h, transfer_gate.h),
// the protocol itself the core library cnc_bridge_xmodem.
#include "dnc_node.h"

#include <boost/scope_exit.hpp>

#include <chrono>
#include <exception>
#include <filesystem>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/ros/request_boundary.h"
#include "dnc_drip_handlers.h"

namespace cnc_bridge
{

DncNode::DncNode(ros::NodeHandle nh, ros::NodeHandle pnh) : DncNode(nh, pnh, dncSettings(pnh)) {}

DncNode::DncNode(ros::NodeHandle nh, ros::NodeHandle pnh, const dnc::TransferSettings& settings)
    : nh_(nh),
      pnh_(pnh),
      serial_(settings.link.serial),
      default_protocol_(settings.default_protocol),
      keep_open_(settings.keep_open),
      xmodem_config_(settings.xmodem),
      text_options_(settings.text),
      feedback_period_(ros::Duration(settings.feedback_period)),
      open_link_(linkFactory(settings.link)),
      port_lock_(settings.link.lockDevice(), settings.lock_dir)
{
  std::error_code ignored;
  std::filesystem::create_directories(settings.program_dir, ignored);  // ProgramDirectory reports what fails
  programs_ = std::make_unique<ProgramDirectory>(settings.program_dir);
  protected_ = std::make_unique<programs::ProtectedRange>(
      settings.protected_programs, settings.allow_protected_programs, "~allow_protected_programs");
  name_pattern_ = std::make_unique<programs::NamePattern>(settings.name_pattern);
  archive_ = std::make_unique<programs::ProgramArchive>(
      settings.archive_dir.empty() ? programs_->root() + ".archive" : settings.archive_dir, settings.archive_keep);
  files_ = std::make_unique<dnc::TransferFiles>(*programs_, *protected_, *name_pattern_, *archive_);
  // ~enable_motion (bool, default false) and ~set_motion_enabled: a drip-feed (a goal or a
  // control's request answered by drip) runs the program on the control as it arrives.
  motion_ = std::make_unique<RuntimeSwitch>(pnh, "motion", "enable_motion", "set_motion_enabled");

  for (const char* name : {"xmodem", "xmodem-crc", "xmodem-1k"})
  {
    registerProtocol(name, [this](Transport& link, const TransferJob& job, const auto& feedback, const auto& cancel)
                     { return runXmodem(link, job, feedback, cancel); });
  }

  state_ = std::make_unique<MachineStatePublisher>(nh, pnh, settings.link.hardwareId());
  state_->update(
      [&](MachineState& s)
      {
        s.mode = MachineState::MODE_DNC;
        s.execution = MachineState::EXECUTION_READY;
      });
  state_->setLink(LinkState::kDown, "port opened on demand");
  state_->diagnostics().add("Transfers", this, &DncNode::transferDiagnostics);
  // DNC drip-feed (drip) and program backup (backup): ~drip_* and ~backup_* parameters,
  // dnc/current_line (docs/dnc_drip_feed.md).
  registerDripProtocols(*this, nh, pnh, serial_, *state_, feedback_period_);
  // Program requests punched by the control (~requests, ~request_mode; dnc_requests.cpp).
  setUpRequests(nh, pnh);

  if (keep_open_)
  {
    try
    {
      openLink();
    }
    catch (const Error& e)
    {
      ROS_ERROR("%s (retried at the next transfer)", e.what());
    }
  }

  send_srv_ = advertiseGuardedService(pnh, "send_program", &DncNode::onSend, this);
  receive_srv_ = advertiseGuardedService(pnh, "receive_program", &DncNode::onReceive, this);
  // ~transfer: a goal arriving while a transfer runs is rejected with the reason, the running one
  // goes on (dnc_transfer_action.cpp).
  startTransferAction();
  ROS_INFO("dnc_node on %s, programs in %s, default protocol %s", serial_.describe().c_str(), programs_->root().c_str(),
           default_protocol_.c_str());
}

DncNode::~DncNode()
{
  stopRequests();
  cancelRunning();
  action_.reset();  // waits for the running goal to end
}

bool DncNode::tryReserve(const std::string& what)
{
  if (gate_.tryReserve(what))  // the request listener leaves the port (runReserved waits for it)
    return true;
  counters_.refused();
  return false;
}

std::string DncNode::busyMessage()
{
  return dnc::busyRefusal(serial_.device, gate_.running(), pnh_.resolveName("transfer") + "/cancel");
}

void DncNode::registerProtocol(const std::string& protocol, ProtocolHandler handler)
{
  protocols_[protocol] = std::move(handler);
}

Transport& DncNode::openLink()
{
  std::lock_guard<std::mutex> lock(link_mutex_);
  if (!link_ || !link_->isOpen())
  {
    state_->setLink(LinkState::kConnecting, "opening " + serial_.describe());
    try
    {
      // What the control sent while the port was closed stays (TransferSettings::link), as it does
      // in a port kept open (~keep_open): a receiving control's NAK, queued before a send starts,
      // is its start request.
      link_ = open_link_();
      ++link_generation_;
    }
    catch (const Error& e)
    {
      link_.reset();
      state_->setLink(LinkState::kDown, e.what());
      throw;
    }
    // An empty message would leave "opening ..." in state (setLink keeps the previous one).
    state_->setLink(LinkState::kUp, "port open");
  }
  return *link_;
}

void DncNode::closeLink()
{
  std::lock_guard<std::mutex> lock(link_mutex_);
  link_.reset();
  state_->setLink(LinkState::kDown, keep_open_ ? "port closed after a link error" : "port opened on demand");
}

TransferResult DncNode::run(TransferGoal goal, const Feedback& feedback)
{
  if (!tryReserve("a " + goal.direction + "_program service call for " + goal.file))
  {
    TransferResult result;
    result.message = busyMessage();
    return result;
  }
  // Released however the transfer ends.
  BOOST_SCOPE_EXIT_ALL(this)
  {
    gate_.release();
  };
  bool cancelled = false;
  return runReserved(std::move(goal), feedback, cancelled);
}

TransferResult DncNode::runReserved(TransferGoal goal, const Feedback& feedback, bool& cancelled)
{
  TransferResult result;
  cancelled = false;
  if (goal.protocol.empty())
    goal.protocol = default_protocol_;
  TransferJob job;
  job.goal = goal;
  job.send = goal.direction == TransferGoal::DIRECTION_SEND;
  const auto handler = protocols_.find(goal.protocol);
  result.message = checkJob(job);
  if (!result.message.empty())
    return result;
  counters_.started();
  const std::string transfer_message = (job.send ? "sending " : "receiving ") + goal.file + " (" + goal.protocol + ")";
  state_->update(
      [&](MachineState& s)
      {
        s.execution = MachineState::EXECUTION_ACTIVE;
        s.program = goal.file;
        s.block = 0;
        s.message = transfer_message;
      });
  ROS_INFO("%s %s by %s", job.send ? "sending" : "receiving", job.path.c_str(), goal.protocol.c_str());
  // Left by an unexpected error (answered at the request boundary): counted, and the state does
  // not stay active.
  const int exceptions = std::uncaught_exceptions();
  BOOST_SCOPE_EXIT_ALL(this, exceptions, &goal)
  {
    if (std::uncaught_exceptions() <= exceptions)
      return;
    const std::string message = "the transfer of " + goal.file + " ended by an unexpected error";
    counters_.finished(false, false, 0, 0, 0, message);
    state_->update(
        [&](MachineState& s)
        {
          s.execution = MachineState::EXECUTION_STOPPED;
          s.message = message;
        });
  };
  result = runOnPort(handler->second, job, transfer_message, feedback, cancelled);
  endTransfer(job, result, cancelled);
  return result;
}

std::string DncNode::checkJob(TransferJob& job)
{
  const TransferGoal& goal = job.goal;
  if (protocols_.count(goal.protocol) == 0)
  {
    std::string known;
    for (const auto& p : protocols_)
      known += (known.empty() ? "" : ", ") + p.first;
    return "refused: unknown protocol '" + goal.protocol + "' (known: " + known + ")";
  }
  if (goal.direction != TransferGoal::DIRECTION_SEND && goal.direction != TransferGoal::DIRECTION_RECEIVE)
    return "refused: direction must be 'send' or 'receive', not '" + goal.direction + "'";
  const dnc::JobCheck check = files_->check(goal.file, job.send);
  if (!check.accepted())
  {
    if (check.counted)
      counters_.refused();
    return check.refusal;
  }
  job.path = check.path;
  // A drip-feed runs the program on the control as it arrives (in DNC mode the control executes
  // each block it receives): the motion switch gates it, as it gates every node's motion.
  if (job.send && goal.protocol == "drip" && !motion_->enabled())
    return "refused: " + motion_->refusal("a drip-feed (the control runs it as it arrives)");
  if (job.send)
    job.check_contents = files_->sendCheck(goal.file);
  return "";
}

TransferResult DncNode::runOnPort(const ProtocolHandler& handler, const TransferJob& job,
                                  const std::string& transfer_message, const Feedback& feedback, bool& cancelled)
{
  TransferResult result;
  gate_.waitForListenerToLeave();
  // The port lock and (unless ~keep_open) the port are released however the transfer ends; at
  // once after it, before the archive is written.
  const auto release_port = [this](PortLock* lock)
  {
    if (!keep_open_)
      closeLink();
    lock->unlock();
  };
  std::unique_ptr<PortLock, decltype(release_port)> port_held(&port_lock_, release_port);
  try
  {
    // A status poller on the same line (haas_mdc_node) skips its polls while this is held. It
    // holds the lock itself for the length of one query (under a second), so a busy lock is tried
    // again for a while before the transfer is refused.
    if (!port_lock_.lockForTransfer(std::chrono::seconds(2), [this] { return gate_.cancelFlag().load(); }))
      throw LinkError(serial_.device + " is in use by another process (port lock " + port_lock_.lockFile() + ")");
    Transport& link = openLink();
    // Opening the port set its own message: while the transfer runs, state says what it is.
    state_->update([&](MachineState& s) { s.message = transfer_message; });
    result = handler(link, job, feedback, gate_.cancelFlag());
    // A protocol that reports a cancel in its result (drip, backup) rather than by CancelledError.
    cancelled = !result.success && gate_.cancelFlag();
  }
  catch (const CancelledError& e)
  {
    cancelled = true;
    result.success = false;
    result.message = e.what();
  }
  catch (const LinkError& e)
  {
    result.success = false;
    result.message = e.what();
    closeLink();  // reopened at the next transfer
  }
  catch (const Error& e)
  {
    result.success = false;
    result.message = e.what();
  }
  return result;
}

void DncNode::endTransfer(const TransferJob& job, const TransferResult& result, bool cancelled)
{
  counters_.finished(result.success, cancelled, result.blocks, result.retries, result.bytes, result.message);
  state_->update(
      [&](MachineState& s)
      {
        s.execution = result.success ? MachineState::EXECUTION_READY : MachineState::EXECUTION_STOPPED;
        s.message = result.message;
      });
  if (result.success)
  {
    ROS_INFO("%s", result.message.c_str());
    archiveProgram(job);
    if (!job.send)
      reportRequestInTransfer(job);
  }
  else
  {
    ROS_ERROR("%s", result.message.c_str());
  }
}

void DncNode::archiveProgram(const TransferJob& job)
{
  try
  {
    const std::string kept =
        files_->archive(job.path, {"dnc_node", state_->machineName(), job.send ? "sent" : "received"});
    if (!kept.empty())
      ROS_INFO("%s", kept.c_str());
  }
  catch (const Error& e)
  {
    // The transfer itself succeeded: an archive that cannot be written is reported, not a failure.
    ROS_ERROR("%s was moved but not archived: %s", job.path.substr(job.path.find_last_of('/') + 1).c_str(), e.what());
  }
}

TransferResult DncNode::runXmodem(Transport& link, const TransferJob& job,
                                  const std::function<void(const TransferFeedback&)>& feedback,
                                  const std::atomic<bool>& cancel)
{
  dnc::ProgressThrottle throttle(feedback_period_.toSec());
  auto progress = [&](const xmodem::Progress& p)
  {
    if (!throttle.due(ros::Time::now().toSec(), p))
      return;
    TransferFeedback f;
    f.bytes = p.bytes;
    f.total = p.total;
    f.block = p.block;
    f.retries = p.retries;
    f.percent = p.total > 0 ? static_cast<float>(100.0 * p.bytes / p.total) : 0.0f;
    if (feedback)
      feedback(f);
    state_->update([&](MachineState& s) { s.block = p.block; });
  };
  // The protected range is checked again on the bytes read for sending (the file is opened once):
  // a program saved over the file since the request was checked is not sent.
  const xmodem::FileResult file = dnc::transferByXmodem(link, job.path, job.send, job.goal.protocol, xmodem_config_,
                                                        text_options_, progress, cancel, counters_, job.check_contents);
  TransferResult result;
  result.success = true;
  result.message = file.message;
  result.bytes = file.file_bytes;
  result.blocks = file.stats.blocks;
  result.retries = file.stats.retries;
  return result;
}

void DncNode::cancelRunning()
{
  gate_.cancelFlag() = true;
  std::lock_guard<std::mutex> lock(link_mutex_);
  if (link_)
    link_->interrupt();
}

void DncNode::transferDiagnostics(diagnostic_updater::DiagnosticStatusWrapper& status)
{
  const dnc::TransferTotals totals = counters_.totals();
  if (totals.lastFailed())
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "last transfer failed: " + totals.last_result);
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK,
                   totals.last_result.empty() ? "no transfer yet" : totals.last_result);
  for (const auto& [name, value] : totals.fields(requests_))
    status.add(name, value);
  status.add("default protocol", default_protocol_);
  status.add("program_dir", programs_->root());
}
}  // namespace cnc_bridge

// Four threads: a service call may run a whole transfer; keep serving meanwhile.
int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::DncNode>(argc, argv, "dnc_node", {4});
}
