// dnc_node: NC program transfer between ~program_dir and a control's RS-232 port (see dnc_node.h
// and docs/dnc_node.md). This file holds the parameters, the serial link, state and diagnostics,
// the run of one transfer, and the XModem protocol handler; the action and services are in
// dnc_transfer_action.cpp. The rules a transfer follows (one at a time, the files it may touch,
// the archive, the counters) are the core's (cnc_bridge/dnc/transfer_rules.h, transfer_gate.h),
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
#include "cnc_bridge/xmodem/network_waits.h"
#include "dnc_drip_handlers.h"

namespace cnc_bridge
{
namespace
{
// XModem timing (seconds) and limits; defaults are the protocol's (docs/protocols/xmodem.md#timeouts-and-limits).
dnc::XmodemWaits xmodemWaits(const ros::NodeHandle& pnh, bool networked)
{
  dnc::XmodemWaits waits;
  // ~start_timeout: receiving, how long to wait for the control to start sending (the operator
  // starts the punch on the control), NAK repeated every ~nak_interval meanwhile.
  waits.start_timeout = params::seconds(pnh, "start_timeout", 120.0);
  waits.nak_interval = params::seconds(pnh, "nak_interval", 10.0);
  // ~start_wait: sending, how long to wait for the control's NAK (the operator starts the receive).
  waits.start_wait = params::seconds(pnh, "start_wait", 120.0);
  // ~block_timeout: receiving, wait for the next packet before a NAK.
  waits.block_timeout = params::seconds(pnh, "block_timeout", 10.0);
  // ~ack_timeout: sending, wait for ACK/NAK after a packet before sending it again.
  waits.ack_timeout = params::seconds(pnh, "ack_timeout", 10.0);
  // ~eot_quiet: receiving, silence after EOT before it is believed (a garbled SOH looks like EOT).
  waits.eot_quiet = params::seconds(pnh, "eot_quiet", 0.03);
  // ~wait_characters (int), ~wait_floor (s): the longest gap between two bytes of a packet and the
  // silence that ends the purge of a garbled packet before a NAK, in character times of the line,
  // at least wait_floor. 0 (the launch file's) or not set: 30 and 0.03 s on a cable (1 s at 300
  // baud, 30 ms at 9600 and above), 140 and 0.2 s at a device server (xmodem/network_waits.h).
  const int characters = pnh.param("wait_characters", 0);
  waits.wait_characters = characters > 0 ? static_cast<unsigned>(characters)
                          : networked    ? xmodem::kNetworkWaitCharacters
                                         : 30u;
  const double floor = pnh.param("wait_floor", 0.0);
  waits.wait_floor = floor > 0   ? Milliseconds(static_cast<int64_t>(floor * 1000.0))
                     : networked ? xmodem::kNetworkWaitFloor
                                 : Milliseconds(30);
  // ~char_timeout, ~purge_quiet (s, default 0: from the line rate as above): fixed values instead.
  if (pnh.param("char_timeout", 0.0) > 0)
    waits.char_timeout = params::seconds(pnh, "char_timeout", 1.0);
  if (pnh.param("purge_quiet", 0.0) > 0)
    waits.purge_quiet = params::seconds(pnh, "purge_quiet", 1.0);
  // ~max_retries (int, default 10): errors in a row on one block before the transfer aborts.
  const int max_retries = pnh.param("max_retries", 10);
  if (max_retries < 1)
    ROS_WARN("~max_retries %d is below 1; using 10", max_retries);
  waits.max_retries = max_retries < 1 ? 10u : static_cast<unsigned>(max_retries);
  return waits;
}
}  // namespace

DncNode::DncNode(ros::NodeHandle nh, ros::NodeHandle pnh)
    : nh_(nh),
      pnh_(pnh),
      serial_(params::serialSettings(pnh, 115200)),
      // ~lock_dir (string, default /run/lock/cnc_bridge): directory of the serial-port lock shared with a status
      // poller on the same line (haas_mdc_node ~lock_dir; both must name the same directory).
      port_lock_(serial_.device, pnh.param<std::string>("lock_dir", kDefaultLockDir))
{
  // ~program_dir (string, required): the only directory files are read from and written to;
  // created if it does not exist.
  const std::string program_dir = params::required<std::string>(pnh, "program_dir");
  std::error_code ignored;
  std::filesystem::create_directories(program_dir, ignored);  // ProgramDirectory reports what fails
  programs_ = std::make_unique<ProgramDirectory>(program_dir);
  // ~protected_programs (string, default "O08000-O09999"; "" for none): program numbers never
  // sent (by any protocol) unless ~allow_protected_programs (bool, default false) is set. A Haas
  // keeps its probing/WIPS and OEM macros there. The number is taken from the file name (by
  // ~name_pattern, default "O%05d.nc") and from the program's first block.
  protected_ = std::make_unique<programs::ProtectedRange>(pnh.param<std::string>("protected_programs", "O08000-O09999"),
                                                          pnh.param("allow_protected_programs", false),
                                                          "~allow_protected_programs");
  name_pattern_ = std::make_unique<programs::NamePattern>(pnh.param<std::string>("name_pattern", "O%05d.nc"));
  // ~archive_dir (string, default <program_dir>.archive), ~archive_keep (int, default 20): every
  // program sent or received is kept there, one folder per program, distinct versions only
  // (docs/share_node.md, "Program archive").
  archive_ =
      std::make_unique<programs::ProgramArchive>(pnh.param<std::string>("archive_dir", programs_->root() + ".archive"),
                                                 static_cast<unsigned>(std::max(1, pnh.param("archive_keep", 20))));
  files_ = std::make_unique<dnc::TransferFiles>(*programs_, *protected_, *name_pattern_, *archive_);
  // ~enable_motion (bool, default false) and ~set_motion_enabled: a drip-feed (a goal or a
  // control's request answered by drip) runs the program on the control as it arrives.
  motion_ = std::make_unique<RuntimeSwitch>(pnh, "motion", "enable_motion", "set_motion_enabled");
  // ~xmodem_mode (string, default "xmodem"): protocol when a request leaves it empty. A Haas
  // speaks XModem checksum only (xmodem); xmodem-crc and xmodem-1k suit PC-based controls.
  pnh.param<std::string>("xmodem_mode", default_protocol_, "xmodem");
  xmodem::parseMode(default_protocol_);  // fails early on a typo
  // ~keep_open (bool, default false): keep the port open between transfers (otherwise it is opened
  // for each transfer, so other programs can use the port in between).
  pnh.param("keep_open", keep_open_, false);
  // ~eob (string, default "lf"): the control's end-of-block pattern, Haas setting 25
  // (lf, cr, crlf, crcr, lflf). Programs are sent with it.
  text_options_.control_eob = xmodem::parseEob(pnh.param<std::string>("eob", "lf"));
  // ~eob_checksum (string, default "wire"): how the control sums a checksum-mode packet holding
  // ends of block: wire (the bytes sent, as every XModem) or lf (each end of block as LF, as one
  // description of the Haas has it). A receive that meets the other reading says so.
  text_options_.eob_checksum = xmodem::parseEobChecksum(pnh.param<std::string>("eob_checksum", "wire"));
  // ~file_eob (string, default "lf"): line ends of programs stored in ~program_dir.
  text_options_.file_eob = xmodem::parseEob(pnh.param<std::string>("file_eob", "lf"));
  // ~binary (bool, default false): move bytes exactly (no EOB conversion; received files keep the
  // SUB padding of the last block).
  pnh.param("binary", text_options_.binary, false);
  xmodem_config_ = dnc::xmodemConfig(xmodemWaits(pnh, parseSerialAddress(serial_.device).networked()),
                                     serial_.charactersPerSecond());
  xmodem_config_.eob_checksum_name = pnh.resolveName("eob_checksum");
  // ~max_program_bytes (int, default 16 MiB): the longest program moved by XModem.
  dnc::setMaxProgramBytes(xmodem_config_,
                          pnh.param("max_program_bytes", static_cast<int>(xmodem::kDefaultMaxProgramBytes)),
                          "~max_program_bytes");
  // ~feedback_rate (Hz, default 20): action feedback at most this often (and after the last block).
  feedback_period_ = ros::Duration(1.0 / params::positive(pnh, "feedback_rate", 20.0));

  for (const char* name : {"xmodem", "xmodem-crc", "xmodem-1k"})
  {
    registerProtocol(name, [this](Transport& link, const TransferJob& job, const auto& feedback, const auto& cancel)
                     { return runXmodem(link, job, feedback, cancel); });
  }

  state_ = std::make_unique<MachineStatePublisher>(nh, pnh, serial_.describe());
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
  // ~transfer: an ActionServer (not a SimpleActionServer, whose new goal preempts the running
  // one): a goal arriving while a transfer runs is rejected with the reason, the running one goes
  // on. Accepted goals run in worker_.
  worker_ = std::thread([this] { actionWorker(); });
  action_ = std::make_unique<actionlib::ActionServer<TransferAction>>(
      pnh, "transfer", [this](GoalHandle goal) { onGoal(goal); }, [this](GoalHandle goal) { onCancel(goal); }, false);
  action_->start();
  ROS_INFO("dnc_node on %s, programs in %s, default protocol %s", serial_.describe().c_str(), programs_->root().c_str(),
           default_protocol_.c_str());
}

DncNode::~DncNode()
{
  stopRequests();
  cancelRunning();
  {
    std::lock_guard<std::mutex> lock(goal_mutex_);
    stopping_ = true;
  }
  goal_ready_.notify_all();
  if (worker_.joinable())
    worker_.join();
  action_.reset();
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
      // What the control sent while the port was closed stays, as it does in a port kept open
      // (~keep_open): a receiving control's NAK, queued before a send starts, is its start request.
      link_ = openSerialLine(serial_, InputOnOpen::kKeep);
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
  const auto handler = protocols_.find(goal.protocol);
  if (handler == protocols_.end())
  {
    std::string known;
    for (const auto& p : protocols_)
      known += (known.empty() ? "" : ", ") + p.first;
    result.message = "refused: unknown protocol '" + goal.protocol + "' (known: " + known + ")";
    return result;
  }
  if (goal.direction != TransferGoal::DIRECTION_SEND && goal.direction != TransferGoal::DIRECTION_RECEIVE)
  {
    result.message = "refused: direction must be 'send' or 'receive', not '" + goal.direction + "'";
    return result;
  }
  TransferJob job;
  job.send = goal.direction == TransferGoal::DIRECTION_SEND;
  job.goal = goal;
  const dnc::JobCheck check = files_->check(goal.file, job.send);
  if (!check.accepted())
  {
    result.message = check.refusal;
    if (check.counted)
      counters_.refused();
    return result;
  }
  job.path = check.path;
  // A drip-feed runs the program on the control as it arrives (in DNC mode the control executes
  // each block it receives): the motion switch gates it, as it gates every node's motion.
  if (job.send && goal.protocol == "drip" && !motion_->enabled())
  {
    result.message = "refused: " + motion_->refusal("a drip-feed (the control runs it as it arrives)");
    return result;
  }
  if (job.send)
    job.check_contents = files_->sendCheck(goal.file);
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

  gate_.waitForListenerToLeave();
  // The port lock and (unless ~keep_open) the port are released however the transfer ends; at
  // once after it (reset() below), before the archive is written.
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
    result = handler->second(link, job, feedback, gate_.cancelFlag());
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
  port_held.reset();

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
  return result;
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
