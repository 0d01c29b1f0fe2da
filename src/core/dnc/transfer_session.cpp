// dnc_node's transfers (include/cnc_bridge/dnc/transfer_session.h): the serial link, one transfer
// run start to end, and the XModem protocol handler. The program requests are in
// transfer_session_requests.cpp.
#include "cnc_bridge/dnc/transfer_session.h"

#include <boost/scope_exit.hpp>

#include <chrono>
#include <exception>
#include <filesystem>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge::dnc
{
namespace
{
std::unique_ptr<ProgramDirectory> makeProgramDirectory(const std::string& root)
{
  std::error_code ignored;
  std::filesystem::create_directories(root, ignored);  // ProgramDirectory reports what fails
  return std::make_unique<ProgramDirectory>(root);
}

std::string archiveRoot(const TransferSettings& settings, const ProgramDirectory& programs)
{
  return settings.archive_dir.empty() ? programs.root() + ".archive" : settings.archive_dir;
}

TransferListener& listenerOf(const SessionParts& parts)
{
  if (parts.listener == nullptr || parts.motion == nullptr)
    throw ConfigError("a transfer session needs a listener and a motion switch");
  return *parts.listener;
}
}  // namespace

TransferSession::TransferSession(const TransferSettings& settings, const RequestSettings& requests,
                                 const SessionParts& parts)
    : settings_(settings),
      requests_(requests),
      listener_(listenerOf(parts)),
      motion_(*parts.motion),
      machine_(parts.machine),
      cancel_topic_(parts.cancel_topic),
      keep_open_(settings.keep_open || requests.enabled),
      request_protocol_(requests.listener.wire == RequestWire::kXmodem ? settings.default_protocol : "drip"),
      programs_(makeProgramDirectory(settings.program_dir)),
      protected_(settings.protected_programs, settings.allow_protected_programs, "~allow_protected_programs"),
      name_pattern_(settings.name_pattern),
      archive_(archiveRoot(settings, *programs_), settings.archive_keep),
      files_(*programs_, protected_, name_pattern_, archive_),
      open_link_(parts.open_link ? parts.open_link : linkFactory(settings.link)),
      port_lock_(settings.link.lockDevice(), settings.lock_dir)
{
  for (const char* name : {"xmodem", "xmodem-crc", "xmodem-1k"})
  {
    registerProtocol(name, [this](Transport& link, const TransferJob& job, const auto& progress, const auto& cancel)
                     { return runXmodem(link, job, progress, cancel); });
  }
}

TransferSession::~TransferSession()
{
  stop();
}

void TransferSession::registerProtocol(const std::string& protocol, ProtocolHandler handler)
{
  protocols_[protocol] = std::move(handler);
}

void TransferSession::start()
{
  if (requests_.enabled && !settings_.keep_open)
    CNC_LOG_INFO("~requests holds the port open (as ~keep_open)");
  if (keep_open_)
  {
    try
    {
      openLink();
    }
    catch (const Error& e)
    {
      CNC_LOG_ERROR(e.what() << " (retried at the next transfer)");
    }
  }
  if (!requests_.enabled)
    return;
  request_thread_ = std::thread([this] { requestWorker(); });
  CNC_LOG_INFO("listening for program requests on " << device() << " (" << requests_.mode << ")");
}

bool TransferSession::tryReserve(const std::string& what)
{
  if (gate_.tryReserve(what))  // the request listener leaves the port (runReserved waits for it)
    return true;
  counters_.refused();
  return false;
}

std::string TransferSession::busyMessage() const
{
  return busyRefusal(device(), gate_.running(), cancel_topic_);
}

Transport& TransferSession::openLink()
{
  std::lock_guard<std::mutex> lock(link_mutex_);
  if (!link_ || !link_->isOpen())
  {
    listener_.onLink(LinkState::kConnecting, "opening " + settings_.link.serial.describe());
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
      listener_.onLink(LinkState::kDown, e.what());
      throw;
    }
    // An empty message would leave "opening ..." in the state (the previous message stays).
    listener_.onLink(LinkState::kUp, "port open");
  }
  return *link_;
}

void TransferSession::closeLink()
{
  std::lock_guard<std::mutex> lock(link_mutex_);
  link_.reset();
  listener_.onLink(LinkState::kDown, keep_open_ ? "port closed after a link error" : "port opened on demand");
}

void TransferSession::cancelRunning()
{
  gate_.cancelFlag() = true;
  std::lock_guard<std::mutex> lock(link_mutex_);
  if (link_)
    link_->interrupt();
}

TransferOutcome TransferSession::run(TransferRequest request, const ProgressFunction& progress)
{
  if (!tryReserve("a " + request.direction + "_program service call for " + request.file))
  {
    TransferOutcome outcome;
    outcome.message = busyMessage();
    return outcome;
  }
  // Released however the transfer ends.
  BOOST_SCOPE_EXIT_ALL(this)
  {
    gate_.release();
  };
  return runReserved(std::move(request), progress);
}

TransferOutcome TransferSession::runReserved(TransferRequest request, const ProgressFunction& progress)
{
  TransferOutcome outcome;
  if (request.protocol.empty())
    request.protocol = settings_.default_protocol;
  TransferJob job;
  job.request = request;
  job.send = request.direction == kDirectionSend;
  outcome.message = checkJob(job);
  if (!outcome.message.empty())
    return outcome;
  counters_.started();
  const std::string transfer_message =
      (job.send ? "sending " : "receiving ") + request.file + " (" + request.protocol + ")";
  state({Execution::kActive, request.file, 0u, transfer_message});
  CNC_LOG_INFO((job.send ? "sending " : "receiving ") << job.path << " by " << request.protocol);
  // Left by an unexpected error (answered at the node's request boundary): counted, and the state
  // does not stay active.
  const int exceptions = std::uncaught_exceptions();
  BOOST_SCOPE_EXIT_ALL(this, exceptions, &request)
  {
    if (std::uncaught_exceptions() <= exceptions)
      return;
    const std::string message = "the transfer of " + request.file + " ended by an unexpected error";
    counters_.finished(false, false, 0, 0, 0, message);
    state({Execution::kStopped, std::nullopt, std::nullopt, message});
  };
  outcome = runOnPort(protocols_.at(request.protocol), job, transfer_message, progress);
  endTransfer(job, outcome);
  return outcome;
}

std::string TransferSession::checkJob(TransferJob& job)
{
  const TransferRequest& request = job.request;
  if (protocols_.count(request.protocol) == 0)
  {
    std::string known;
    for (const auto& p : protocols_)
      known += (known.empty() ? "" : ", ") + p.first;
    return "refused: unknown protocol '" + request.protocol + "' (known: " + known + ")";
  }
  if (request.direction != kDirectionSend && request.direction != kDirectionReceive)
    return "refused: direction must be 'send' or 'receive', not '" + request.direction + "'";
  const JobCheck check = files_.check(request.file, job.send);
  if (!check.accepted())
  {
    if (check.counted)
      counters_.refused();
    return check.refusal;
  }
  job.path = check.path;
  // A drip-feed runs the program on the control as it arrives (in DNC mode the control executes
  // each block it receives): the motion switch gates it, as it gates every node's motion.
  if (job.send && request.protocol == "drip" && !motion_.enabled())
    return "refused: " + motion_.refusal("a drip-feed (the control runs it as it arrives)");
  if (job.send)
    job.check_contents = files_.sendCheck(request.file);
  return "";
}

TransferOutcome TransferSession::runOnPort(const ProtocolHandler& handler, const TransferJob& job,
                                           const std::string& transfer_message, const ProgressFunction& progress)
{
  TransferOutcome outcome;
  gate_.waitForListenerToLeave();
  // The port lock and (unless kept open) the port are released however the transfer ends; at
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
      throw LinkError(device() + " is in use by another process (port lock " + port_lock_.lockFile() + ")");
    Transport& link = openLink();
    // Opening the port set its own message: while the transfer runs, the state says what it is.
    state({std::nullopt, std::nullopt, std::nullopt, transfer_message});
    outcome = handler(link, job, progress, gate_.cancelFlag());
    // A protocol that reports a cancel in its outcome (drip, backup) rather than by CancelledError.
    outcome.cancelled = !outcome.success && gate_.cancelFlag();
  }
  catch (const CancelledError& e)
  {
    outcome = TransferOutcome{};
    outcome.cancelled = true;
    outcome.message = e.what();
  }
  catch (const LinkError& e)
  {
    outcome = TransferOutcome{};
    outcome.message = e.what();
    closeLink();  // reopened at the next transfer
  }
  catch (const Error& e)
  {
    outcome = TransferOutcome{};
    outcome.message = e.what();
  }
  return outcome;
}

void TransferSession::endTransfer(const TransferJob& job, const TransferOutcome& outcome)
{
  counters_.finished(outcome.success, outcome.cancelled, outcome.blocks, outcome.retries, outcome.bytes,
                     outcome.message);
  state({outcome.success ? Execution::kReady : Execution::kStopped, std::nullopt, std::nullopt, outcome.message});
  if (!outcome.success)
  {
    CNC_LOG_ERROR(outcome.message);
    return;
  }
  CNC_LOG_INFO(outcome.message);
  archiveProgram(job);
  if (!job.send)
    reportRequestInTransfer(job);
}

void TransferSession::archiveProgram(const TransferJob& job)
{
  try
  {
    const std::string kept = files_.archive(job.path, {"dnc_node", machine_, job.send ? "sent" : "received"});
    if (!kept.empty())
      CNC_LOG_INFO(kept);
  }
  catch (const Error& e)
  {
    // The transfer itself succeeded: an archive that cannot be written is reported, not a failure.
    CNC_LOG_ERROR(job.path.substr(job.path.find_last_of('/') + 1) << " was moved but not archived: " << e.what());
  }
}

TransferOutcome TransferSession::runXmodem(Transport& link, const TransferJob& job, const ProgressFunction& progress,
                                           const std::atomic<bool>& cancel)
{
  ProgressThrottle throttle(settings_.feedback_period);
  const auto start = std::chrono::steady_clock::now();
  auto report = [&](const xmodem::Progress& p)
  {
    const std::chrono::duration<double> elapsed = std::chrono::steady_clock::now() - start;
    // The throttle's clock starts at 0: the first block is reported at once, as on a node's clock.
    if (!throttle.due(elapsed.count() + settings_.feedback_period, p))
      return;
    TransferProgress f;
    f.bytes = p.bytes;
    f.total = p.total;
    f.block = p.block;
    f.retries = p.retries;
    f.percent =
        p.total > 0 ? static_cast<float>(100.0 * static_cast<double>(p.bytes) / static_cast<double>(p.total)) : 0.0f;
    if (progress)
      progress(f);
    state({std::nullopt, std::nullopt, p.block, std::nullopt});
  };
  // The protected range is checked again on the bytes read for sending (the file is opened once):
  // a program saved over the file since the request was checked is not sent.
  const xmodem::FileResult file = transferByXmodem(link, job.path, job.send, job.request.protocol, settings_.xmodem,
                                                   settings_.text, report, cancel, counters_, job.check_contents);
  TransferOutcome outcome;
  outcome.success = true;
  outcome.message = file.message;
  outcome.bytes = file.file_bytes;
  outcome.blocks = file.stats.blocks;
  outcome.retries = file.stats.retries;
  return outcome;
}
}  // namespace cnc_bridge::dnc
