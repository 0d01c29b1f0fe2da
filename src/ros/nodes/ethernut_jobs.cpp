// ethernut_node's ~run_job action (src/ros/nodes/ethernut_node.h): a goal loads an
// ethernut::Job (refused before anything is sent if it is bad), publishes its preview, then the
// core ethernut::JobStreamer streams it segment by segment, carrying out the program's own steps
// between two segments (docs/ethernut_node.md); JobView shows its calls as feedback and state.
#include <cmath>

#include "ethernut_node.h"

namespace cnc_bridge
{
/// A running job's calls (the streamer's, its runner's) as the action's feedback and state.
class EthernutNode::JobView : public ethernut::StreamListener
{
 public:
  JobView(EthernutNode& node, uint64_t count) : node_(node)
  {
    feedback_.coordinate_count = static_cast<uint32_t>(count);
  }

  bool cancelRequested() override { return node_.action_.isPreemptRequested() || !ros::ok(); }
  // Read at each M01, as an operator flips the control's OPT STOP switch during a job.
  bool optionalStop() override { return node_.pnh_.param("optional_stop", true); }
  void stepReached(const gcode::ProgramStep& step) override { feedback_.line = step.line; }
  void stepDone(const gcode::ProgramStep& step, const JobFeedback& feedback) override
  {
    using Kind = gcode::ProgramStep::Kind;
    switch (step.kind)
    {
      case Kind::kToolChange:
        node_.state_->update([&](MachineState& m) { m.tool = step.tool; });
        break;
      case Kind::kSpindle:
        node_.state_->update([&](MachineState& m)
                             { m.spindle_speed = step.spindle == gcode::Spindle::kOff ? 0.0 : step.spindle_rpm; });
        break;
      case Kind::kCoolant:
        node_.state_->update([&](MachineState& m)
                             { m.coolant = step.coolant ? MachineState::COOLANT_ON : MachineState::COOLANT_OFF; });
        break;
      default:
        break;
    }
    publish(feedback);
  }
  void dwelling(const JobFeedback& feedback) override
  {
    node_.state_->update([&](MachineState& m) { m.message = feedback.event; });
    publish(feedback);
  }
  void optionalStopPassed(const JobFeedback& feedback) override { publish(feedback); }
  // Held at the program's M00 (or M01) until ~resume; nothing is sent meanwhile.
  void holding(const JobFeedback& feedback, uint32_t line) override
  {
    node_.state_->update(
        [&](MachineState& m)
        {
          m.execution = MachineState::EXECUTION_PAUSED;
          m.block = line;
          m.message = feedback.event;
        });
    ROS_INFO_STREAM("run_job: " << feedback.event);
    publish(feedback);
  }
  void resumed(const std::string& what) override
  {
    node_.state_->update(
        [&](MachineState& m)
        {
          m.execution = MachineState::EXECUTION_ACTIVE;
          m.message = "resumed after the " + what;
        });
  }
  void progress(const ethernut::StreamProgress& p, const JobFeedback& feedback) override
  {
    feedback_.line = p.line;
    feedback_.coordinate_index = p.done > 0 ? static_cast<uint32_t>(p.done - 1) : 0;
    feedback_.percent = p.count > 0 ? static_cast<float>(100.0 * p.done / p.count) : 100.0f;
    feedback_.resends = p.resends;
    feedback_.commanded.x = p.last.x * kMetresPerMm;
    feedback_.commanded.y = p.last.y * kMetresPerMm;
    feedback_.commanded.z = p.last.z * kMetresPerMm;
    publish(feedback);
    node_.state_->update([&](MachineState& m) { m.block = p.line; });
  }
  void motionHoldChanged(const JobFeedback& feedback, bool board_holds) override
  {
    ROS_INFO_STREAM("run_job: " << feedback.event);
    node_.state_->update([&](MachineState& m) { m.message = feedback.event; });
    publish(feedback);
    if (!board_holds)
    {
      // Held before its next segment: nothing streams until the hold ends.
      node_.state_->update(
          [&](MachineState& m)
          { m.execution = feedback.paused ? MachineState::EXECUTION_PAUSED : MachineState::EXECUTION_ACTIVE; });
    }
  }

 private:
  void publish(const JobFeedback& feedback)
  {
    feedback_.event = feedback.event;
    feedback_.paused = feedback.paused;
    node_.action_.publishFeedback(feedback_);
  }

  EthernutNode& node_;
  RunJobFeedback feedback_;
};

void EthernutNode::execute(const RunJobGoalConstPtr& goal)
{
  RunJobResult result;
  if (!motion_->enabled())
  {
    abortGoal(result, motion_->refusal("job"));  // before anything is loaded or sent
    return;
  }
  std::string why;
  auto c = client(why);
  if (!c)
  {
    abortGoal(result, why);
    return;
  }
  const JobRunner::Scope goal_scope(jobs_->runner());  // a disable from here on holds the goal
  if (c->state() == ethernut::SessionState::kPaused)
  {
    abortGoal(result, "the board is paused (a cancelled job holds its move there): call " + pnh_.resolveName("resume") +
                          " first");
    return;
  }
  std::string program;
  const std::shared_ptr<ethernut::Job> job = loadJob(*goal, program, why);
  if (!job)
  {
    abortGoal(result, why);
    return;
  }
  publishPreview(job->preview());
  state_->update(
      [&](MachineState& m)
      {
        m.program = program;
        m.block = 0;
      });
  ROS_INFO_STREAM("run_job: streaming " << job->coordinateCount() << " coordinates of " << program);
  JobView view(*this, job->coordinateCount());
  endGoal(jobs_->run(*c, job, view));
}

// The goal's end as the streamer reports it.
void EthernutNode::endGoal(const ethernut::StreamOutcome& outcome)
{
  RunJobResult result;
  result.coordinates_done = static_cast<uint32_t>(outcome.done);
  result.coordinate_count = static_cast<uint32_t>(outcome.count);
  result.resends = outcome.resends;
  result.message = outcome.message;
  result.success = outcome.completed;
  if (outcome.program_end)
  {
    state_->update([&](MachineState& m) { m.message = outcome.message; });
  }
  if (outcome.cancelled_at_step)
  {
    state_->update(
        [&](MachineState& m)
        {
          m.execution = MachineState::EXECUTION_STOPPED;
          m.message = outcome.message;
        });
  }
  switch (outcome.end)
  {
    case ethernut::StreamOutcome::End::kSucceeded:
      action_.setSucceeded(result, result.message);
      break;
    case ethernut::StreamOutcome::End::kCancelled:
      action_.setPreempted(result, result.message);
      break;
    case ethernut::StreamOutcome::End::kAborted:
      abortGoal(result, result.message);
      break;
  }
}

void EthernutNode::abortGoal(RunJobResult& result, const std::string& message)
{
  result.success = false;
  result.message = message;
  ROS_WARN_STREAM("run_job: " << message);
  action_.setAborted(result, message);
}

// Loads the goal's job (its count and preview before the first set is sent, a bad program refused
// before it runs); \returns nothing, with \p refusal, if it is refused.
std::shared_ptr<ethernut::Job> EthernutNode::loadJob(const RunJobGoal& goal, std::string& program, std::string& refusal)
{
  program = goal.file.empty() ? "(points)" : goal.file;
  return goal.file.empty() ? loadPoints(goal, refusal) : loadProgram(goal, refusal);
}

std::shared_ptr<ethernut::Job> EthernutNode::loadProgram(const RunJobGoal& goal, std::string& refusal)
{
  const std::string machine_frame = state_->frame("machine");
  if (!goal.header.frame_id.empty() && goal.header.frame_id != machine_frame)
  {
    // A program's coordinates are its own work coordinates, streamed as they are.
    refusal = "job refused: a G-code job is streamed in the program's coordinates; header.frame_id (\"" +
              goal.header.frame_id + "\") applies to points only and must be empty or \"" + machine_frame + "\"";
    return nullptr;
  }
  if (!program_dir_)
  {
    refusal = "G-code jobs need ~program_dir (" + pnh_.resolveName("program_dir") + ")";
    return nullptr;
  }
  try
  {
    std::shared_ptr<ethernut::Job> job =
        ethernut::Job::fromProgram(program_dir_->resolveExisting(goal.file), settings_.jobs.parser, settings_.jobs.g53,
                                   settings_.jobs.max_preview_points, settings_.jobs.soft_limits);
    if (!job->skippedSummary().empty())
    {
      ROS_WARN_STREAM("run_job: " << goal.file << ": " << job->skippedSummary() << " (" << settings_.jobs.g53.setting
                                  << ": skip)");
    }
    return job;
  }
  catch (const Error& e)
  {
    refusal = std::string("job refused: ") + e.what();
    return nullptr;
  }
}

// Points in another frame (the cell's world, a robot's base) into the machine frame, mm.
std::shared_ptr<ethernut::Job> EthernutNode::loadPoints(const RunJobGoal& goal, std::string& refusal)
{
  if (goal.points.empty())
  {
    refusal = "job refused: neither a file nor points given";
    return nullptr;
  }
  ToMachineFrame::Transform transform;
  try
  {
    transform = to_machine_->lookup(state_->frame("machine"), goal.header.frame_id, "points");
  }
  catch (const Error& e)
  {
    refusal = std::string("job refused: ") + e.what();
    return nullptr;
  }
  std::vector<ethernut::Coordinate> points;
  for (const auto& given : goal.points)
  {
    const geometry_msgs::Point p = ToMachineFrame::apply(transform, given);
    try
    {
      // Every point is checked before the first is sent.
      points.push_back(ethernut::boardCoordinate(p.x / kMetresPerMm, p.y / kMetresPerMm, p.z / kMetresPerMm,
                                                 settings_.jobs.soft_limits, "point " + std::to_string(points.size())));
    }
    catch (const Error& e)
    {
      refusal = std::string("job refused: ") + e.what();
      return nullptr;
    }
  }
  return ethernut::Job::fromPoints(std::move(points), settings_.jobs.max_preview_points);
}

}  // namespace cnc_bridge
