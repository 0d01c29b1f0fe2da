// The drip and backup protocol handlers of dnc_node: ROS parameters to core options, core
// progress to action feedback, state and dnc/current_line. One transfer at a time (dnc_node
// serialises them), so the handlers hold no lock of their own.
#include "dnc_drip_handlers.h"

#include "dnc_commanded_position.h"

#include <std_srvs/Trigger.h>

#include <memory>
#include <mutex>

#include "cnc_bridge/DncLine.h"
#include "cnc_bridge/PlanDrip.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/backup.h"
#include "cnc_bridge/dnc/dnc_codes.h"
#include "cnc_bridge/dnc/drip_feed.h"
#include "cnc_bridge/ros/params.h"
#include "cnc_bridge/ros/request_boundary.h"

namespace cnc_bridge
{
namespace
{
/// A duration parameter in seconds where 0 means "no limit" (params::seconds() wants > 0).
Milliseconds secondsOrZero(const ros::NodeHandle& pnh, const std::string& name, double fallback)
{
  double value = pnh.param(name, fallback);
  if (!(value >= 0))
  {
    ROS_WARN("%s must be >= 0 seconds, not %g; using %g", pnh.resolveName(name).c_str(), value, fallback);
    value = fallback;
  }
  return Milliseconds(static_cast<int64_t>(value * 1000.0));
}

/// Sets the line's flow control for the drip-feed for the length of one transfer: XON/XOFF is read
/// by the feed itself (so neither the kernel nor a device server may act on DC1/DC3), RTS/CTS is
/// the driver's (or the device server's, over RFC 2217). The node's own settings come back
/// afterwards (applySettings()).
class FlowControlGuard
{
 public:
  FlowControlGuard(Transport& link, dnc::DripFlow flow) : line_(dynamic_cast<SerialLine*>(&link))
  {
    if (line_ == nullptr)
    {
      return;  // not a serial line (tests): nothing to set
    }
    line_->setFlowControl(flow == dnc::DripFlow::kRtsCts ? FlowControl::kRtsCts : FlowControl::kNone);
  }
  ~FlowControlGuard()
  {
    if (line_ == nullptr)
    {
      return;
    }
    try
    {
      line_->applySettings();
    }
    catch (const Error& e)
    {
      // The feed's outcome stands; a line that failed is opened and set up afresh next time.
      ROS_WARN("drip-feed: cannot restore the line settings of %s: %s", line_->settings().describe().c_str(), e.what());
    }
  }
  FlowControlGuard(const FlowControlGuard&) = delete;
  FlowControlGuard& operator=(const FlowControlGuard&) = delete;

 private:
  SerialLine* line_;
};

class DripHandlers
{
 public:
  DripHandlers(ros::NodeHandle nh, ros::NodeHandle pnh, const SerialSettings& serial, MachineStatePublisher& state,
               ros::Duration feedback_period)
      : state_(state), commanded_(nh, pnh, state)
  {
    // ~drip_eob (string, default "lf"): end of block sent after each line: lf (ISO, Fanuc), cr
    // (EIA), crlf (Haas), lfcr, lfcrcr.
    drip_.eob = dnc::parseEob(pnh.param<std::string>("drip_eob", "lf"));
    // ~drip_flow (string, default "xonxoff"): xonxoff (DC3/DC1 read by the node, parity bit
    // masked), rtscts (the port's hardware handshake), none.
    drip_.flow = dnc::parseDripFlow(pnh.param<std::string>("drip_flow", "xonxoff"));
    // ~drip_pace (bool, default true): write no faster than the line carries (baud / bits per
    // character), so at most ~drip_xoff_allowance characters can follow an XOFF.
    if (pnh.param("drip_pace", true))
    {
      drip_.pace_cps = serial.charactersPerSecond();
    }
    // ~drip_realtime_priority (int, default 0): SCHED_FIFO priority of the feeding thread while a
    // feed runs (0 = normal scheduler). Keeps the pacing on time on a loaded machine; needs
    // CAP_SYS_NICE (a warning and the normal scheduler without it).
    drip_.realtime_priority = std::max(0, pnh.param("drip_realtime_priority", 0));
    // ~drip_chunk (int, default 4): characters per write.
    drip_.chunk = static_cast<size_t>(std::max(1, pnh.param("drip_chunk", 4)));
    // ~drip_xoff_allowance (int, default 10): characters the control takes after its XOFF (Fanuc: 10).
    drip_.xoff_allowance = static_cast<size_t>(std::max(1, pnh.param("drip_xoff_allowance", 10)));
    // ~drip_add_percent (bool, default true): frame with '%' when the file does not.
    pnh.param("drip_add_percent", drip_.add_percent, true);
    // ~drip_leader, ~drip_trailer (int, default 0): leader/trailer characters (tape feed).
    drip_.leader_length = static_cast<size_t>(std::max(0, pnh.param("drip_leader", 0)));
    drip_.trailer_length = static_cast<size_t>(std::max(0, pnh.param("drip_trailer", 0)));
    // ~drip_leader_char (string, default "nul"): nul, lf or space.
    const std::string leader_char = pnh.param<std::string>("drip_leader_char", "nul");
    if (leader_char == "nul")
      drip_.leader_char = 0;
    else if (leader_char == "lf")
      drip_.leader_char = '\n';
    else if (leader_char == "space")
      drip_.leader_char = ' ';
    else
      throw ConfigError(pnh.resolveName("drip_leader_char") + " must be nul, lf or space, not '" + leader_char + "'");
    // ~dc_codes (bool, default false): DC2 before and DC4 after the program (Haas setting 14).
    pnh.param("dc_codes", drip_.dc_codes, false);
    // ~drip_allow_lowercase (bool, default false): lowercase passes the check (8N1 controls that
    // take it in comments); under ISO (7E1) leave it off.
    drip_.rules.reject_lowercase = !pnh.param("drip_allow_lowercase", false);
    // ~drip_hold_timeout (s, default 0 = wait forever): longest XOFF before ~drip_hold_action.
    drip_.hold_timeout = secondsOrZero(pnh, "drip_hold_timeout", 0.0);
    // ~drip_hold_action (string, default "fail"): fail, or resume (assume the XON was lost).
    const std::string hold_action = pnh.param<std::string>("drip_hold_action", "fail");
    if (hold_action != "fail" && hold_action != "resume")
      throw ConfigError(pnh.resolveName("drip_hold_action") + " must be fail or resume, not '" + hold_action + "'");
    drip_.on_hold_timeout = hold_action == "resume" ? dnc::HoldTimeoutAction::kResume : dnc::HoldTimeoutAction::kFail;
    // ~drip_wait_for_dc1 (bool, default false): send nothing until the control asks (DC1);
    // ~drip_start_timeout (s, default 0 = forever) bounds that wait.
    pnh.param("drip_wait_for_dc1", drip_.wait_for_dc1, false);
    drip_.start_timeout = secondsOrZero(pnh, "drip_start_timeout", 0.0);
    drip_.progress_interval = Milliseconds(static_cast<int64_t>(feedback_period.toSec() * 1000));
    drip_.validate();

    // ~backup_start_timeout (s, default 120; 0 = forever): wait for the control to start punching.
    backup_.start_timeout = secondsOrZero(pnh, "backup_start_timeout", 120.0);
    // ~backup_quiet_timeout (s, default 5): silence that ends a program punched without closing '%'.
    backup_.quiet_timeout = params::seconds(pnh, "backup_quiet_timeout", 5.0);
    // ~backup_send_dc1 (bool, default true): send DC1 when ready to receive.
    pnh.param("backup_send_dc1", backup_.send_dc1, true);
    backup_.progress_interval = drip_.progress_interval;

    line_pub_ = nh.advertise<DncLine>("dnc/current_line", 100);
  }

  /// ~pause, ~resume and ~plan_drip; \p programs resolves the files ~plan_drip reads.
  void advertise(ros::NodeHandle pnh, const ProgramDirectory& programs)
  {
    programs_ = &programs;
    pause_srv_ = advertiseGuardedService(pnh, "pause", &DripHandlers::onPause, this);
    resume_srv_ = advertiseGuardedService(pnh, "resume", &DripHandlers::onResume, this);
    plan_srv_ = advertiseGuardedService(pnh, "plan_drip", &DripHandlers::onPlan, this);
  }

  TransferResult drip(Transport& link, const TransferJob& job,
                      const std::function<void(const TransferFeedback&)>& feedback, const std::atomic<bool>& cancel)
  {
    if (!job.send)
      throw ConfigError("drip sends a program to the control; to store one from it use protocol backup");
    dnc::RestartPoint restart;
    restart.line = job.goal.start_line;
    restart.block = job.goal.start_block;
    dnc::DripOptions options = drip_;
    options.cancel = &cancel;
    options.check_head = job.check_contents;  // the protected range, on the head the feed sends
    const dnc::DripPlan plan = dnc::planDrip(job.path, options, restart, job.goal.restart_preamble);
    if (restart.active())
    {
      ROS_INFO("restart at line %lu of %s; sent before it:\n%s", static_cast<unsigned long>(plan.scan.start_line),
               job.goal.file.c_str(), plan.preamble.c_str());
      for (const auto& warning : plan.scan.warnings)
        ROS_WARN("%s", warning.c_str());
    }
    FlowControlGuard guard(link, options.flow);
    dnc::DripSender sender(link, options);
    ActiveSender active(*this, sender);
    CommandedPositionScope commanded(commanded_, plan.preamble);  // dnc/commanded_position and tf
    bool was_held = false;
    bool was_paused = false;
    const auto progress = [&](const dnc::DripProgress& p)
    {
      TransferFeedback f;
      f.bytes = p.bytes;
      f.total = p.total;
      f.line = static_cast<uint32_t>(p.line);
      f.block_number = p.block;
      f.percent = static_cast<float>(p.percent());
      f.held = p.held;
      f.paused = p.paused;
      if (feedback)
        feedback(f);
      commanded_.refresh();
      state_.update(
          [&](MachineState& s)
          {
            s.block = static_cast<uint32_t>(p.line);
            if (p.held != was_held || p.paused != was_paused)
            {
              const bool stopped = p.held || p.paused;
              s.execution = stopped ? MachineState::EXECUTION_PAUSED : MachineState::EXECUTION_ACTIVE;
              s.message = p.paused ? "drip-feed paused by the operator (~resume to go on)"
                          : p.held ? "drip-feed held by the control (XOFF)"
                                   : "drip-feeding " + job.goal.file;
            }
          });
      was_held = p.held;
      was_paused = p.paused;
    };
    const auto line_sent = [&](uint64_t line, const std::string& text)
    {
      commanded_.lineSent(text);
      if (line_pub_.getNumSubscribers() == 0)
        return;
      DncLine msg;
      msg.header.stamp = ros::Time::now();
      msg.program = job.goal.file;
      msg.line = static_cast<uint32_t>(line);
      std::string block;
      if (!text.empty())
        block = dnc::sequenceNumber(text);
      msg.block_number = block;
      msg.text = text;
      line_pub_.publish(msg);
    };
    const dnc::DripResult r = sender.send(plan, progress, line_sent);
    TransferResult result;
    result.success = r.completed();
    result.message = r.message;
    if (r.xoff_events > 0)
      result.message += "; largest output queue at an XOFF " + std::to_string(r.max_queued_at_xoff) + " characters";
    result.bytes = r.bytes;
    result.stopped_at_line = static_cast<uint32_t>(r.stopped_at_line);
    result.stopped_at_block = r.stopped_at_block;
    return result;
  }

  TransferResult backup(Transport& link, const TransferJob& job,
                        const std::function<void(const TransferFeedback&)>& feedback, const std::atomic<bool>& cancel)
  {
    if (job.send)
      throw ConfigError("backup stores a program the control punches; to send one use protocol drip or xmodem");
    dnc::BackupOptions options = backup_;
    options.cancel = &cancel;
    dnc::BackupReceiver receiver(link, options);
    const auto progress = [&](const dnc::BackupProgress& p)
    {
      TransferFeedback f;
      f.bytes = p.bytes;
      f.line = static_cast<uint32_t>(p.line);
      if (feedback)
        feedback(f);
      state_.update([&](MachineState& s) { s.block = static_cast<uint32_t>(p.line); });
    };
    const dnc::BackupResult r = receiver.receive(job.path, progress);
    TransferResult result;
    result.success = true;
    result.message = r.message;
    result.bytes = r.bytes;
    result.stopped_at_line = static_cast<uint32_t>(r.lines);
    return result;
  }

 private:
  /// Makes a running sender reachable from ~pause and ~resume for the length of one feed.
  class ActiveSender
  {
   public:
    ActiveSender(DripHandlers& handlers, dnc::DripSender& sender) : handlers_(handlers)
    {
      std::lock_guard<std::mutex> lock(handlers_.sender_mutex_);
      handlers_.sender_ = &sender;
    }
    ~ActiveSender()
    {
      std::lock_guard<std::mutex> lock(handlers_.sender_mutex_);
      handlers_.sender_ = nullptr;
    }
    ActiveSender(const ActiveSender&) = delete;
    ActiveSender& operator=(const ActiveSender&) = delete;

   private:
    DripHandlers& handlers_;
  };

  bool onPause(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response)
  {
    std::lock_guard<std::mutex> lock(sender_mutex_);
    if (sender_ == nullptr)
    {
      response.message = "refused: no drip-feed is running (pause applies to protocol drip)";
      return true;
    }
    response.success = true;
    response.message = sender_->paused() ? "already paused" : "paused: nothing more is sent until ~resume";
    sender_->pause();
    state_.update(
        [&](MachineState& s)
        {
          s.execution = MachineState::EXECUTION_PAUSED;
          s.message = "drip-feed paused by the operator (~resume to go on)";
        });
    ROS_INFO("drip-feed paused");
    return true;
  }

  bool onResume(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response)
  {
    std::lock_guard<std::mutex> lock(sender_mutex_);
    if (sender_ == nullptr)
    {
      response.message = "refused: no drip-feed is running (resume applies to a paused drip-feed)";
      return true;
    }
    if (!sender_->paused())
    {
      response.message = "refused: the drip-feed is not paused";
      return true;
    }
    sender_->resume();
    response.success = true;
    response.message = "resumed";
    ROS_INFO("drip-feed resumed");
    return true;
  }

  bool onPlan(PlanDrip::Request& request, PlanDrip::Response& response)
  {
    try
    {
      const std::string path = programs_->resolveExisting(request.file);
      dnc::RestartPoint restart;
      restart.line = request.start_line;
      restart.block = request.start_block;
      const dnc::ProgramScan scan =
          dnc::scanProgram(path, drip_.rules, restart, drip_.eob.size(), drip_.max_line_length);
      response.resume_line = static_cast<uint32_t>(scan.start_line);
      response.resume_block = blockAtLine(path, scan.start_line);
      response.warnings = scan.warnings;
      if (restart.active())
        response.preamble = request.restart_preamble.empty() ? scan.computed_preamble : request.restart_preamble;
      for (const auto& issue : scan.issues)
        response.character_issues.push_back(issue.describe());
      response.character_issue_count = scan.issue_count;
      const auto preamble_issues = dnc::checkPreamble(response.preamble, drip_.rules);
      for (const auto& issue : preamble_issues)
        response.character_issues.push_back("restart preamble " + issue.describe());
      response.character_issue_count += preamble_issues.size();
      if (response.character_issue_count == 0)
        response.total_bytes = dnc::planDrip(path, drip_, restart, request.restart_preamble).total_bytes;
      response.success = true;
      response.message = response.character_issue_count == 0
                             ? "ready: " + std::to_string(response.total_bytes) + " bytes from line " +
                                   std::to_string(response.resume_line)
                             : std::to_string(response.character_issue_count) +
                                   " character(s) the control cannot take: a feed would be refused";
    }
    catch (const Error& e)
    {
      response.success = false;
      response.message = e.what();
    }
    return true;
  }

  /// The sequence number of line \p number of the file ("" if it has none).
  std::string blockAtLine(const std::string& path, uint64_t number) const
  {
    dnc::LineReader reader(path, drip_.max_line_length);
    std::string line;
    while (reader.next(line))
    {
      if (reader.lineNumber() == number)
        return dnc::sequenceNumber(line);
    }
    return "";
  }

  MachineStatePublisher& state_;
  CommandedPositionPublisher commanded_;
  const ProgramDirectory* programs_ = nullptr;
  std::mutex sender_mutex_;
  dnc::DripSender* sender_ = nullptr;  ///< the feed running, for ~pause / ~resume
  ros::ServiceServer pause_srv_;
  ros::ServiceServer resume_srv_;
  ros::ServiceServer plan_srv_;
  dnc::DripOptions drip_;
  dnc::BackupOptions backup_;
  ros::Publisher line_pub_;
};
}  // namespace

void registerDripProtocols(DncNode& node, ros::NodeHandle nh, ros::NodeHandle pnh, const SerialSettings& serial,
                           MachineStatePublisher& state, ros::Duration feedback_period)
{
  auto handlers = std::make_shared<DripHandlers>(nh, pnh, serial, state, feedback_period);
  handlers->advertise(pnh, node.programs());
  node.registerProtocol("drip", [handlers](Transport& link, const TransferJob& job, const auto& feedback,
                                           const auto& cancel) { return handlers->drip(link, job, feedback, cancel); });
  node.registerProtocol("backup",
                        [handlers](Transport& link, const TransferJob& job, const auto& feedback, const auto& cancel)
                        { return handlers->backup(link, job, feedback, cancel); });
}
}  // namespace cnc_bridge
