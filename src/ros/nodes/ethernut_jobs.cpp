// ethernut_node's ~run_job action (src/ros/nodes/ethernut_node.h): a goal loads an
// ethernut::Job (refused before anything is sent if it is bad), publishes its preview, then streams
// it segment by segment, carrying out the program's own steps between two segments
// (docs/ethernut_node.md).
#include <cmath>

#include "ethernut_node.h"

namespace cnc_bridge
{
EthernutNode::GoalScope::GoalScope(EthernutNode& node) : node_(node)
{
  node_.motion_hold_.setGoalRunning(true);
}

EthernutNode::GoalScope::~GoalScope()
{
  node_.motion_hold_.setGoalRunning(false);
  std::lock_guard<std::mutex> lock(node_.job_mutex_);
  node_.running_job_.reset();
}

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
  const GoalScope goal_scope(*this);
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
  {
    std::lock_guard<std::mutex> lock(job_mutex_);
    running_job_ = job;
  }
  runJob(*c, job);
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
        ethernut::Job::fromProgram(program_dir_->resolveExisting(goal.file), parser_options_, g53_,
                                   static_cast<size_t>(max_preview_points_), soft_limits_);
    if (!job->skippedSummary().empty())
    {
      ROS_WARN_STREAM("run_job: " << goal.file << ": " << job->skippedSummary() << " (" << g53_.setting << ": skip)");
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
                                                 soft_limits_, "point " + std::to_string(points.size())));
    }
    catch (const Error& e)
    {
      refusal = std::string("job refused: ") + e.what();
      return nullptr;
    }
  }
  return ethernut::Job::fromPoints(std::move(points), static_cast<size_t>(max_preview_points_));
}

// The job runs as segments: the moves up to the program's next own step (stop, dwell, spindle,
// coolant, tool change), which the node carries out between two segments, or its end.
void EthernutNode::runJob(ethernut::Client& c, const std::shared_ptr<ethernut::Job>& job)
{
  RunJobResult result;
  RunJobFeedback feedback;
  const uint64_t count = job->coordinateCount();
  feedback.coordinate_count = static_cast<uint32_t>(count);
  Totals totals;
  bool cancelled = false;
  const auto preempted = [&](const std::string& message)
  {
    result.coordinates_done = static_cast<uint32_t>(totals.done);
    result.coordinate_count = static_cast<uint32_t>(count);
    result.resends = totals.resends;
    result.message = message;
    action_.setPreempted(result, result.message);
  };
  for (;;)
  {
    {
      std::lock_guard<std::mutex> lock(job_mutex_);
      job_ = JobProgress();
    }
    job->startSegment();
    try
    {
      if (!startSegment(c, job, feedback, cancelled))
      {
        preempted("cancelled while held (" + feedback.event + ")");
        return;
      }
    }
    catch (const Error& e)
    {
      abortGoal(result, e.what());
      return;
    }
    const JobProgress p = followSegment(c, feedback, count, totals, cancelled);
    totals.done += p.done;
    totals.resends += p.resends;
    const auto step = p.outcome == ethernut::JobOutcome::kCompleted ? job->stepAtEnd() : std::nullopt;
    if (!step || step->kind == gcode::ProgramStep::Kind::kEnd)
    {
      result.coordinates_done = static_cast<uint32_t>(totals.done);
      result.coordinate_count = static_cast<uint32_t>(count);
      result.resends = totals.resends;
      finishJob(p, step, cancelled, job->skippedSummary(), result);
      return;
    }
    if (!carryOut(*step, feedback, cancelled))
    {
      const std::string message = "cancelled at the " + step->describe();
      state_->update(
          [&](MachineState& m)
          {
            m.execution = MachineState::EXECUTION_STOPPED;
            m.message = message;
          });
      preempted(message);
      return;
    }
  }
}

// Ends the goal after its last segment: \p step is the program's end (M02/M30) if it has one.
void EthernutNode::finishJob(const JobProgress& p, const std::optional<gcode::ProgramStep>& step, bool cancelled,
                             const std::string& skipped, RunJobResult& result)
{
  result.message = step ? step->describe() + ": the job ends here; nothing after it was sent" : p.message;
  if (!skipped.empty())
  {
    result.message += "; " + skipped;
  }
  result.success = p.outcome == ethernut::JobOutcome::kCompleted;
  if (step)
  {
    state_->update([&](MachineState& m) { m.message = result.message; });
  }
  if (cancelled)
  {
    action_.setPreempted(result, result.message);
  }
  else if (result.success)
  {
    action_.setSucceeded(result, result.message);
  }
  else
  {
    abortGoal(result, result.message);
  }
}

// Starts the next segment of moves once motion is allowed: enabled, and no hold left from a
// disable during this job (~resume, refused while motion is disabled, ends the hold). The check
// and the start are one step under the motion switch's gate, so a disable either comes before (the job is
// held here) or after (it pauses the board). \returns false if the goal was cancelled while held.
// \throws Error from Client::startJob.
bool EthernutNode::startSegment(ethernut::Client& c, const std::shared_ptr<ethernut::Job>& job,
                                RunJobFeedback& feedback, bool& cancelled)
{
  for (;;)
  {
    std::string hold;
    uint64_t resumes = 0;
    {
      const auto gate = motion_->core().gate();
      const ethernut::MotionHold::Snapshot now = motion_hold_.snapshot();
      hold = now.hold;
      resumes = now.resumes;
      if (motion_->enabled() && hold.empty())
      {
        // The source keeps the job alive for as long as the client holds it.
        c.startJob([job](ethernut::Coordinate& out) { return job->next(out); });
        return true;
      }
    }
    if (hold.empty())
    {
      hold = "motion disabled";  // onMotionSwitched has not run yet; it names the caller
    }
    showMotionHold(hold, "", false, feedback);
    state_->update([&](MachineState& m) { m.execution = MachineState::EXECUTION_PAUSED; });
    if (!motion_hold_.waitForResume(resumes, goalCancelled(cancelled)))
    {
      return false;
    }
    showMotionHold("", hold, false, feedback);
    state_->update([&](MachineState& m) { m.execution = MachineState::EXECUTION_ACTIVE; });
  }
}

// Feedback (and state's message) for a motion hold that began (\p hold) or ended (\p hold empty,
// \p ended the hold that ended).
void EthernutNode::showMotionHold(const std::string& hold, const std::string& ended, bool board_holds,
                                  RunJobFeedback& feedback)
{
  feedback.paused = !hold.empty();
  if (hold.empty())
  {
    feedback.event = "resumed after the hold (" + ended + ")";
  }
  else
  {
    feedback.event = hold + ": " +
                     (board_holds ? "the board holds the move in progress" : "the job holds before its next move") +
                     "; enable motion with " + pnh_.resolveName("set_motion_enabled") +
                     " (std_srvs/SetBool, data: true), then call " + pnh_.resolveName("resume");
  }
  ROS_INFO_STREAM("run_job: " << feedback.event);
  state_->update([&](MachineState& m) { m.message = feedback.event; });
  action_.publishFeedback(feedback);
}

// Streams one segment to its end, with feedback at most every 50 ms (a fast board acknowledges
// thousands of sets per second); a cancel holds the board, then stops streaming.
EthernutNode::JobProgress EthernutNode::followSegment(ethernut::Client& c, RunJobFeedback& feedback, uint64_t count,
                                                      const Totals& totals, bool& cancelled)
{
  uint64_t reported = UINT64_MAX;
  std::string shown_hold;  // the motion hold the last feedback showed
  for (;;)
  {
    std::unique_lock<std::mutex> lock(job_mutex_);
    job_cv_.wait_for(lock, std::chrono::milliseconds(50), [&] { return job_.finished; });
    const JobProgress p = job_;
    lock.unlock();
    const std::string hold = motion_hold_.hold();
    if (hold != shown_hold && !p.finished)
    {
      showMotionHold(hold, shown_hold, true, feedback);
      shown_hold = hold;
    }
    if (p.done != reported && (p.done > 0 || totals.done == 0))
    {
      reported = p.done;
      const uint64_t done = totals.done + p.done;
      feedback.line = p.line;
      feedback.coordinate_index = done > 0 ? static_cast<uint32_t>(done - 1) : 0;
      feedback.percent = count > 0 ? static_cast<float>(100.0 * done / count) : 100.0f;
      feedback.resends = totals.resends + p.resends;
      feedback.commanded.x = p.last.x * kMetresPerMm;
      feedback.commanded.y = p.last.y * kMetresPerMm;
      feedback.commanded.z = p.last.z * kMetresPerMm;
      feedback.paused = !shown_hold.empty();
      action_.publishFeedback(feedback);
      state_->update([&](MachineState& m) { m.block = p.line; });
    }
    if (p.finished)
    {
      return p;
    }
    if (!cancelled && (action_.isPreemptRequested() || !ros::ok()))
    {
      cancelled = true;
      cancelSegment(c);
    }
  }
}

// Cancel: hold the board first (it stops the move in progress), then stop streaming.
void EthernutNode::cancelSegment(ethernut::Client& c)
{
  try
  {
    c.pause();
  }
  catch (const Error& e)
  {
    ROS_WARN_STREAM("run_job: pause on cancel failed: " << e.what());
  }
  c.cancelJob();
}

// Carries out one of the program's own steps between two segments (every set before it is
// acknowledged: the board has moved there). \returns false if the goal was cancelled meanwhile.
bool EthernutNode::carryOut(const gcode::ProgramStep& step, RunJobFeedback& feedback, bool& cancelled)
{
  using Kind = gcode::ProgramStep::Kind;
  feedback.event = step.describe();
  feedback.line = step.line;
  switch (step.kind)
  {
    case Kind::kToolChange:
      state_->update([&](MachineState& m) { m.tool = step.tool; });
      break;
    case Kind::kSpindle:
      state_->update([&](MachineState& m)
                     { m.spindle_speed = step.spindle == gcode::Spindle::kOff ? 0.0 : step.spindle_rpm; });
      break;
    case Kind::kCoolant:
      state_->update([&](MachineState& m)
                     { m.coolant = step.coolant ? MachineState::COOLANT_ON : MachineState::COOLANT_OFF; });
      break;
    case Kind::kDwell:
      state_->update([&](MachineState& m) { m.message = step.describe(); });
      action_.publishFeedback(feedback);
      return program_stop_.waitFor(std::chrono::duration<double>(step.dwell_s), goalCancelled(cancelled));
    case Kind::kOptionalStop:
      // Read at each M01, as an operator flips the control's OPT STOP switch during a job.
      if (!pnh_.param("optional_stop", true))
      {
        feedback.event += " passed (" + pnh_.resolveName("optional_stop") + " false)";
        action_.publishFeedback(feedback);
        return true;
      }
      return holdAtStop(step, feedback, cancelled);
    case Kind::kStop:
      return holdAtStop(step, feedback, cancelled);
    default:
      break;
  }
  action_.publishFeedback(feedback);
  return true;
}

// Holds the job at the program's M00 (or M01) until ~resume; nothing is sent meanwhile.
bool EthernutNode::holdAtStop(const gcode::ProgramStep& step, RunJobFeedback& feedback, bool& cancelled)
{
  feedback.event += ": waiting for " + pnh_.resolveName("resume");
  feedback.paused = true;
  program_stop_.hold(step.describe());  // before the feedback: a resume sent in answer finds it
  state_->update(
      [&](MachineState& m)
      {
        m.execution = MachineState::EXECUTION_PAUSED;
        m.block = step.line;
        m.message = feedback.event;
      });
  ROS_INFO_STREAM("run_job: " << feedback.event);
  action_.publishFeedback(feedback);
  const bool resumed = program_stop_.waitForResume(goalCancelled(cancelled));
  feedback.paused = false;
  if (resumed)
  {
    state_->update(
        [&](MachineState& m)
        {
          m.execution = MachineState::EXECUTION_ACTIVE;
          m.message = "resumed after the " + step.describe();
        });
  }
  return resumed;
}

// The goal's cancel (or ROS shutting down) for a wait; sets \p cancelled when it says so.
JobHold::Cancelled EthernutNode::goalCancelled(bool& cancelled)
{
  return [this, &cancelled]
  {
    const bool now = action_.isPreemptRequested() || !ros::ok();
    cancelled = cancelled || now;
    return now;
  };
}
}  // namespace cnc_bridge
