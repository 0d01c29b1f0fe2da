// at_controller_node: the ~follow_path action (see at_controller_node.h for the whole node): the
// goal mapped to the core's at_protocol::GoalRequest, planned by the session and carried out by
// the goal runner, its feedback, result, job/path and the machine's state while it runs.
#include "at_controller_node.h"

#include <nav_msgs/Path.h>

#include <string>
#include <vector>

namespace cnc_bridge
{
namespace ap = at_protocol;

namespace
{
/// A streaming operation's progress as the action's feedback (its event and paused are the goal's).
AtFollowPathFeedback progressFeedback(const ap::Job& job, const std::array<int32_t, 3>& reported, bool stopping)
{
  AtFollowPathFeedback feedback;
  feedback.setpoint = job.sent();
  feedback.setpoints_total = job.total();
  feedback.progress = job.total() > 0 ? static_cast<float>(job.sent()) / job.total() : 0.0f;
  feedback.commanded = at_controller::toPoint(job.current().position);
  feedback.reported = at_controller::toPoint(reported);
  feedback.following_error.x = feedback.commanded.x - feedback.reported.x;
  feedback.following_error.y = feedback.commanded.y - feedback.reported.y;
  feedback.following_error.z = feedback.commanded.z - feedback.reported.z;
  feedback.stopping = stopping;
  return feedback;
}
}  // namespace

/// One goal as the goal runner reports it: its feedback, and the machine's state.
class AtControllerNode::GoalView : public ap::GoalListener
{
 public:
  GoalView(AtControllerNode& node, const AtFollowPathGoal& goal) : node_(node), goal_(goal) {}

  bool cancelRequested() override { return node_.follow_path_.isPreemptRequested() || !ros::ok() || node_.stopping_; }
  // Read at each M01, as an operator flips the control's OPT STOP switch during a job.
  bool optionalStop() override { return node_.pnh_.param("optional_stop", true); }
  void operationStarted(const ap::Operation& operation) override { node_.showStarted(goal_, operation); }
  void operationProgress(const ap::Job& job, bool stopping, const ap::GoalFeedback& feedback) override
  {
    feedback_ = progressFeedback(job, node_.session_->snapshot().position, stopping);
    if (feedback_.setpoint > 0)
    {
      publish(feedback);
    }
  }
  void operationEnded(const ap::OperationResult& result) override { node_.showEnded(*result.job); }
  void awaitingEnd(const ap::GoalFeedback& feedback) override
  {
    // All setpoints sent: the reported position is what changes while the axes settle.
    feedback_.reported = at_controller::toPoint(node_.session_->snapshot().position);
    feedback_.following_error.x = feedback_.commanded.x - feedback_.reported.x;
    feedback_.following_error.y = feedback_.commanded.y - feedback_.reported.y;
    feedback_.following_error.z = feedback_.commanded.z - feedback_.reported.z;
    feedback_.stopping = false;
    publish(feedback);
  }
  void dwelling(const ap::GoalFeedback& feedback) override
  {
    node_.state_->update([&](MachineState& s) { s.message = feedback.event; });
    publish(feedback);
  }
  void optionalStopPassed(const ap::GoalFeedback& feedback) override { publish(feedback); }
  void holding(const ap::GoalFeedback& feedback, uint32_t line) override
  {
    node_.state_->update(
        [&](MachineState& s)
        {
          s.block = line > 0 ? line : s.block;  // a program stop's line
          s.execution = MachineState::EXECUTION_PAUSED;
          s.message = feedback.event;
        });
    ROS_INFO_STREAM("at_controller_node: follow_path: " << feedback.event);
    feedback_.stopping = false;
    publish(feedback);
  }

 private:
  void publish(const ap::GoalFeedback& feedback)
  {
    feedback_.event = feedback.event;
    feedback_.paused = feedback.paused;
    node_.follow_path_.publishFeedback(feedback_);
  }

  AtControllerNode& node_;
  const AtFollowPathGoal& goal_;
  AtFollowPathFeedback feedback_;
};

/// The goal without ROS types: a path's poses in the machine frame (a pose names its frame, else
/// the path's; empty means the machine frame), in metres.
ap::GoalRequest AtControllerNode::goalRequest(const AtFollowPathGoal& goal)
{
  ap::GoalRequest request;
  request.gcode_file = goal.gcode_file;
  request.has_path = !goal.path.poses.empty();
  request.feed_rate = goal.feed_rate;
  request.coolant = goal.coolant;
  request.spindle_speed = goal.spindle_speed;
  request.tool = goal.tool;
  request.tool_length = goal.tool_length;
  for (const auto& stamped : goal.gcode_file.empty() ? goal.path.poses : decltype(goal.path.poses){})
  {
    const std::string& frame = stamped.header.frame_id.empty() ? goal.path.header.frame_id : stamped.header.frame_id;
    const geometry_msgs::Pose pose =
        ToMachineFrame::apply(to_machine_->lookup(state_->frame("machine"), frame, "path"), stamped.pose);
    request.path_m.push_back({pose.position.x, pose.position.y, pose.position.z});
  }
  return request;
}

/// Publishes the planned corners (pulses) of every operation as job/path in <tf_prefix>machine, metres.
void AtControllerNode::publishPlannedPath(const std::vector<ap::OperationPlan>& plans)
{
  nav_msgs::Path path;
  path.header.stamp = ros::Time::now();
  path.header.frame_id = state_->frame("machine");
  for (size_t p = 0; p < plans.size(); ++p)
  {
    // Each operation starts where the one before ended: that corner once.
    for (size_t i = p == 0 ? 0 : 1; i < plans[p].points.size(); ++i)
    {
      geometry_msgs::PoseStamped pose;
      pose.header = path.header;
      pose.pose.position.x = plans[p].points[i][0] / ap::kPulsesPerMetre;
      pose.pose.position.y = plans[p].points[i][1] / ap::kPulsesPerMetre;
      pose.pose.position.z = plans[p].points[i][2] / ap::kPulsesPerMetre;
      pose.pose.orientation.w = 1.0;
      path.poses.push_back(pose);
    }
  }
  path_pub_.publish(path);
}

/// The goal's operations run by the goal runner: a refusal, a plan that fails or its outcome.
ap::GoalOutcome AtControllerNode::runGoal(const AtFollowPathGoal& goal)
{
  ap::GoalOutcome refused;
  refused.end = ap::GoalOutcome::End::kAborted;
  refused.message = session_->motionRefusal("follow_path");
  if (!refused.message.empty())
  {
    return refused;
  }
  const ap::ControllerSnapshot now = session_->snapshot();
  if (!now.position_valid)
  {
    refused.message = "the controller has not reported its position yet (is the report link up?)";
    return refused;
  }
  try
  {
    // ~program_commands is read at each goal.
    const std::vector<ap::OperationPlan> plans = session_->planGoal(
        goalRequest(goal), now.position, pnh_.param("program_commands", false), pnh_.resolveName("program_commands"));
    publishPlannedPath(plans);  // before motion: the path is known once the goal is accepted
    GoalView view(*this, goal);
    return goal_runner_->run(plans, goal.tool, goal.tool_length, view);
  }
  catch (const std::exception& e)
  {
    refused.message = e.what();
    return refused;
  }
}

void AtControllerNode::followPath(const AtFollowPathGoalConstPtr& goal)
{
  const ap::GoalOutcome outcome = runGoal(*goal);
  AtFollowPathResult result;
  result.success = outcome.end == ap::GoalOutcome::End::kSucceeded;
  result.message = outcome.message;
  result.setpoints = outcome.setpoints;
  result.underruns = static_cast<uint32_t>(outcome.underruns);
  if (outcome.final_position)
  {
    result.final_position = at_controller::toPoint(*outcome.final_position);
  }
  switch (outcome.end)
  {
    case ap::GoalOutcome::End::kSucceeded:
      // The end point confirmed (or the program ended): said after the last operation's "succeeded".
      state_->update(
          [&](MachineState& s)
          { s.message = (outcome.program_end ? "follow_path: " : "follow_path succeeded: ") + outcome.message; });
      return follow_path_.setSucceeded(result, result.message);
    case ap::GoalOutcome::End::kCancelled:
      if (outcome.held_when_cancelled)
      {
        // Cancelled while nothing moved: nothing more was sent.
        state_->update(
            [&](MachineState& s)
            {
              s.execution = MachineState::EXECUTION_STOPPED;
              s.message = result.message;
            });
      }
      return follow_path_.setPreempted(result, result.message);
    case ap::GoalOutcome::End::kAborted:
      ROS_WARN_STREAM("at_controller_node: follow_path: " << result.message);
      if (outcome.setpoints > 0)
      {
        // Also when the operation's last setpoint went out but its end point was never reported.
        state_->update([&](MachineState& s) { s.message = "follow_path aborted: " + result.message; });
      }
      return follow_path_.setAborted(result, result.message);
  }
}

/// state while an operation streams: DNC, its program, coolant, tool and spindle.
void AtControllerNode::showStarted(const AtFollowPathGoal& goal, const ap::Operation& operation)
{
  state_->update(
      [&](MachineState& s)
      {
        s.execution = MachineState::EXECUTION_ACTIVE;
        s.mode = MachineState::MODE_DNC;
        s.coolant = operation.coolant ? MachineState::COOLANT_ON : MachineState::COOLANT_OFF;
        s.program = goal.gcode_file.empty() ? "nav_msgs/Path" : goal.gcode_file;
        if (operation.tool)
        {
          s.tool = operation.tool->tool;
        }
        if (operation.spindle)
        {
          s.spindle_speed = *operation.spindle * session_->options().spindle_max_rpm / ap::kMaxFeed;
        }
      });
}

/// state after an operation: READY, STOPPED (cancel, disable, failure) or ALARM (e-stop).
void AtControllerNode::showEnded(const ap::Job& job)
{
  const ap::ControllerSnapshot now = session_->snapshot();
  state_->update(
      [&](MachineState& s)
      {
        s.execution = now.estop == ap::EStop::kOn                 ? MachineState::EXECUTION_ALARM
                      : job.state() == ap::Job::State::kSucceeded ? MachineState::EXECUTION_READY
                                                                  : MachineState::EXECUTION_STOPPED;
        s.mode = now.jog_axis >= 0 ? MachineState::MODE_MANUAL : MachineState::MODE_AUTO;
        s.coolant = MachineState::COOLANT_OFF;  // #@ ends the operation's coolant
        s.spindle_speed = 0.0;                  // M0@ stops the spindle (step 18)
        s.message = "follow_path " + std::string(ap::Job::toString(job.state())) + ": " + job.message();
      });
}
}  // namespace cnc_bridge
