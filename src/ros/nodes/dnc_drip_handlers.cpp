// The drip and backup protocol handlers of dnc_node: the core's progress to action feedback, state
// and dnc/current_line; ~pause, ~resume and ~plan_drip to the core's dnc::DripProtocols. One
// transfer at a time (the session serialises them), so the handlers hold no lock of their own.
#include "dnc_drip_handlers.h"

#include "dnc_commanded_position.h"

#include <std_srvs/Trigger.h>

#include <memory>

#include "cnc_bridge/DncLine.h"
#include "cnc_bridge/PlanDrip.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/dnc_codes.h"
#include "cnc_bridge/dnc/drip_protocols.h"
#include "cnc_bridge/ros/request_boundary.h"

namespace cnc_bridge
{
namespace
{
class DripHandlers
{
 public:
  DripHandlers(ros::NodeHandle nh, const dnc::DripSettings& settings, MachineStatePublisher& state)
      : protocols_(settings), state_(state), commanded_(nh, state)
  {
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

  dnc::TransferOutcome drip(Transport& link, const dnc::TransferJob& job, const dnc::ProgressFunction& feedback,
                            const std::atomic<bool>& cancel)
  {
    bool was_held = false;
    bool was_paused = false;
    const auto progress = [&](const dnc::DripProgress& p)
    {
      dnc::TransferProgress f;
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
                                   : "drip-feeding " + job.request.file;
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
      msg.program = job.request.file;
      msg.line = static_cast<uint32_t>(line);
      std::string block;
      if (!text.empty())
        block = dnc::sequenceNumber(text);
      msg.block_number = block;
      msg.text = text;
      line_pub_.publish(msg);
    };
    // dnc/commanded_position and tf from the plan's preamble on, ended however the feed ends.
    struct EndOfFeed
    {
      CommandedPositionPublisher& commanded;
      ~EndOfFeed() { commanded.end(); }
    } end_of_feed{commanded_};
    return protocols_.drip(link, job, cancel, progress, line_sent,
                           [this](const dnc::DripPlan& plan) { commanded_.begin(plan.preamble); });
  }

  dnc::TransferOutcome backup(Transport& link, const dnc::TransferJob& job, const dnc::ProgressFunction& feedback,
                              const std::atomic<bool>& cancel)
  {
    const auto progress = [&](const dnc::BackupProgress& p)
    {
      dnc::TransferProgress f;
      f.bytes = p.bytes;
      f.line = static_cast<uint32_t>(p.line);
      if (feedback)
        feedback(f);
      state_.update([&](MachineState& s) { s.block = static_cast<uint32_t>(p.line); });
    };
    return protocols_.backup(link, job, cancel, progress);
  }

 private:
  bool onPause(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response)
  {
    const dnc::SwitchAnswer answer = protocols_.pause();
    response.success = answer.success;
    response.message = answer.message;
    if (!answer.success)
      return true;
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
    const dnc::SwitchAnswer answer = protocols_.resume();
    response.success = answer.success;
    response.message = answer.message;
    if (answer.success)
      ROS_INFO("drip-feed resumed");
    return true;
  }

  bool onPlan(PlanDrip::Request& request, PlanDrip::Response& response)
  {
    dnc::RestartPoint restart;
    restart.line = request.start_line;
    restart.block = request.start_block;
    const dnc::DripPlanAnswer plan = protocols_.plan(*programs_, request.file, restart, request.restart_preamble);
    response.success = plan.success;
    response.message = plan.message;
    response.preamble = plan.preamble;
    response.resume_line = plan.resume_line;
    response.resume_block = plan.resume_block;
    response.warnings = plan.warnings;
    response.character_issues = plan.character_issues;
    response.character_issue_count = plan.character_issue_count;
    response.total_bytes = plan.total_bytes;
    return true;
  }

  dnc::DripProtocols protocols_;
  MachineStatePublisher& state_;
  CommandedPositionPublisher commanded_;
  const ProgramDirectory* programs_ = nullptr;
  ros::ServiceServer pause_srv_;
  ros::ServiceServer resume_srv_;
  ros::ServiceServer plan_srv_;
  ros::Publisher line_pub_;
};
}  // namespace

void registerDripProtocols(dnc::TransferSession& session, ros::NodeHandle nh, ros::NodeHandle pnh,
                           const dnc::DripSettings& settings, MachineStatePublisher& state)
{
  auto handlers = std::make_shared<DripHandlers>(nh, settings, state);
  handlers->advertise(pnh, session.programs());
  session.registerProtocol(
      "drip", [handlers](Transport& link, const dnc::TransferJob& job, const auto& feedback, const auto& cancel)
      { return handlers->drip(link, job, feedback, cancel); });
  session.registerProtocol(
      "backup", [handlers](Transport& link, const dnc::TransferJob& job, const auto& feedback, const auto& cancel)
      { return handlers->backup(link, job, feedback, cancel); });
}
}  // namespace cnc_bridge
