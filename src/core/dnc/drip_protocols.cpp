// dnc_node's drip and backup protocols (include/cnc_bridge/dnc/drip_protocols.h).
#include "cnc_bridge/dnc/drip_protocols.h"

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"
#include "cnc_bridge/dnc/nc_program.h"
#include "cnc_bridge/transport/serial_line.h"

namespace cnc_bridge::dnc
{
namespace
{
/// Sets the line's flow control for the drip-feed for the length of one transfer: XON/XOFF is read
/// by the feed itself (so neither the kernel nor a device server may act on DC1/DC3), RTS/CTS is
/// the driver's (or the device server's, over RFC 2217). The line's own settings come back
/// afterwards (applySettings()).
class FlowControlGuard
{
 public:
  FlowControlGuard(Transport& link, DripFlow flow) : line_(dynamic_cast<SerialLine*>(&link))
  {
    if (line_ == nullptr)
      return;  // not a serial line (tests): nothing to set
    line_->setFlowControl(flow == DripFlow::kRtsCts ? FlowControl::kRtsCts : FlowControl::kNone);
  }
  ~FlowControlGuard()
  {
    if (line_ == nullptr)
      return;
    try
    {
      line_->applySettings();
    }
    catch (const Error& e)
    {
      // The feed's outcome stands; a line that failed is opened and set up afresh next time.
      CNC_LOG_WARN("drip-feed: cannot restore the line settings of " << line_->settings().describe() << ": "
                                                                     << e.what());
    }
  }
  FlowControlGuard(const FlowControlGuard&) = delete;
  FlowControlGuard& operator=(const FlowControlGuard&) = delete;

 private:
  SerialLine* line_;
};
}  // namespace

class DripProtocols::ActiveSender
{
 public:
  ActiveSender(DripProtocols& protocols, DripSender& sender) : protocols_(protocols)
  {
    std::lock_guard<std::mutex> lock(protocols_.sender_mutex_);
    protocols_.sender_ = &sender;
  }
  ~ActiveSender()
  {
    std::lock_guard<std::mutex> lock(protocols_.sender_mutex_);
    protocols_.sender_ = nullptr;
  }
  ActiveSender(const ActiveSender&) = delete;
  ActiveSender& operator=(const ActiveSender&) = delete;

 private:
  DripProtocols& protocols_;
};

TransferOutcome DripProtocols::drip(Transport& link, const TransferJob& job, const std::atomic<bool>& cancel,
                                    const DripSender::ProgressCallback& progress,
                                    const DripSender::LineCallback& line_sent, const PlannedCallback& planned)
{
  if (!job.send)
    throw ConfigError("drip sends a program to the control; to store one from it use protocol backup");
  RestartPoint restart;
  restart.line = job.request.start_line;
  restart.block = job.request.start_block;
  DripOptions options = settings_.drip;
  options.cancel = &cancel;
  options.check_head = job.check_contents;  // the protected range, on the head the feed sends
  const DripPlan plan = planDrip(job.path, options, restart, job.request.restart_preamble);
  if (restart.active())
  {
    CNC_LOG_INFO("restart at line " << plan.scan.start_line << " of " << job.request.file << "; sent before it:\n"
                                    << plan.preamble);
    for (const auto& warning : plan.scan.warnings)
      CNC_LOG_WARN(warning);
  }
  if (planned)
    planned(plan);
  FlowControlGuard guard(link, options.flow);
  DripSender sender(link, options);
  ActiveSender active(*this, sender);
  const DripResult r = sender.send(plan, progress, line_sent);
  TransferOutcome outcome;
  outcome.success = r.completed();
  outcome.message = r.message;
  if (r.xoff_events > 0)
    outcome.message += "; largest output queue at an XOFF " + std::to_string(r.max_queued_at_xoff) + " characters";
  outcome.bytes = r.bytes;
  outcome.stopped_at_line = static_cast<uint32_t>(r.stopped_at_line);
  outcome.stopped_at_block = r.stopped_at_block;
  return outcome;
}

TransferOutcome DripProtocols::backup(Transport& link, const TransferJob& job, const std::atomic<bool>& cancel,
                                      const std::function<void(const BackupProgress&)>& progress)
{
  if (job.send)
    throw ConfigError("backup stores a program the control punches; to send one use protocol drip or xmodem");
  BackupOptions options = settings_.backup;
  options.cancel = &cancel;
  BackupReceiver receiver(link, options);
  const BackupResult r = receiver.receive(job.path, progress);
  TransferOutcome outcome;
  outcome.success = true;
  outcome.message = r.message;
  outcome.bytes = r.bytes;
  outcome.stopped_at_line = static_cast<uint32_t>(r.lines);
  return outcome;
}

SwitchAnswer DripProtocols::pause()
{
  std::lock_guard<std::mutex> lock(sender_mutex_);
  if (sender_ == nullptr)
    return {false, "refused: no drip-feed is running (pause applies to protocol drip)"};
  SwitchAnswer answer{true, sender_->paused() ? "already paused" : "paused: nothing more is sent until ~resume"};
  sender_->pause();
  return answer;
}

SwitchAnswer DripProtocols::resume()
{
  std::lock_guard<std::mutex> lock(sender_mutex_);
  if (sender_ == nullptr)
    return {false, "refused: no drip-feed is running (resume applies to a paused drip-feed)"};
  if (!sender_->paused())
    return {false, "refused: the drip-feed is not paused"};
  sender_->resume();
  return {true, "resumed"};
}

DripPlanAnswer DripProtocols::plan(const ProgramDirectory& programs, const std::string& file,
                                   const RestartPoint& restart, const std::string& restart_preamble) const
{
  DripPlanAnswer answer;
  const DripOptions& drip = settings_.drip;
  try
  {
    const std::string path = programs.resolveExisting(file);
    const ProgramScan scan = scanProgram(path, drip.rules, restart, drip.eob.size(), drip.max_line_length);
    answer.resume_line = static_cast<uint32_t>(scan.start_line);
    answer.resume_block = blockAtLine(path, scan.start_line);
    answer.warnings = scan.warnings;
    if (restart.active())
      answer.preamble = restart_preamble.empty() ? scan.computed_preamble : restart_preamble;
    for (const auto& issue : scan.issues)
      answer.character_issues.push_back(issue.describe());
    answer.character_issue_count = scan.issue_count;
    const auto preamble_issues = checkPreamble(answer.preamble, drip.rules);
    for (const auto& issue : preamble_issues)
      answer.character_issues.push_back("restart preamble " + issue.describe());
    answer.character_issue_count += preamble_issues.size();
    if (answer.character_issue_count == 0)
      answer.total_bytes = planDrip(path, drip, restart, restart_preamble).total_bytes;
    answer.success = true;
    answer.message =
        answer.character_issue_count == 0
            ? "ready: " + std::to_string(answer.total_bytes) + " bytes from line " + std::to_string(answer.resume_line)
            : std::to_string(answer.character_issue_count) +
                  " character(s) the control cannot take: a feed would be refused";
  }
  catch (const Error& e)
  {
    answer.success = false;
    answer.message = e.what();
  }
  return answer;
}

std::string DripProtocols::blockAtLine(const std::string& path, uint64_t number) const
{
  LineReader reader(path, settings_.drip.max_line_length);
  std::string line;
  while (reader.next(line))
  {
    if (reader.lineNumber() == number)
      return sequenceNumber(line);
  }
  return "";
}
}  // namespace cnc_bridge::dnc
