// dnc_node's ~transfer action and its ~send_program / ~receive_program services (docs/dnc_node.md,
// "ROS interface"): an actionlib ActionServer, not a SimpleActionServer, so a goal sent while a
// transfer runs is rejected with the reason and never preempts the running one; accepted goals
// run one at a time in the node's worker thread; a service call runs its transfer to the end.
#include "dnc_node.h"

#include <boost/scope_exit.hpp>

#include "cnc_bridge/ros/request_boundary.h"

namespace cnc_bridge
{
void DncNode::onGoal(GoalHandle goal)
{
  const auto& g = *goal.getGoal();
  if (!tryReserve("goal " + goal.getGoalID().id + " (" + g.direction + " " + g.file + " by " +
                  (g.protocol.empty() ? default_protocol_ : g.protocol) + ")"))
  {
    TransferResult result;
    result.message = busyMessage();
    ROS_WARN("~transfer goal for %s rejected: %s", goal.getGoal()->file.c_str(), result.message.c_str());
    goal.setRejected(result, result.message);
    return;
  }
  goal.setAccepted();
  {
    std::lock_guard<std::mutex> lock(goal_mutex_);
    pending_goal_ = std::make_unique<GoalHandle>(goal);
  }
  goal_ready_.notify_all();
}

void DncNode::onCancel(GoalHandle goal)
{
  std::lock_guard<std::mutex> lock(goal_mutex_);
  if ((current_goal_ && *current_goal_ == goal) || (pending_goal_ && *pending_goal_ == goal))
    cancelRunning();
}

void DncNode::actionWorker()
{
  for (;;)
  {
    GoalHandle goal;
    {
      std::unique_lock<std::mutex> lock(goal_mutex_);
      goal_ready_.wait(lock, [this] { return stopping_ || pending_goal_; });
      if (!pending_goal_)
        return;  // stopping
      current_goal_ = std::move(pending_goal_);
      goal = *current_goal_;
    }
    bool cancelled = false;
    TransferResult result;
    {
      // Free however the transfer ends, and before the result goes out: a client may send its
      // next goal as soon as it has it.
      BOOST_SCOPE_EXIT_ALL(this)
      {
        {
          std::lock_guard<std::mutex> lock(goal_mutex_);
          current_goal_.reset();
        }
        gate_.release();
      };
      if (gate_.cancelFlag())
      {
        cancelled = true;  // cancelled before it started
        result.message = "cancelled before it started";
      }
      else
      {
        result = runGoal(goal, cancelled);
      }
    }
    if (result.success)
      goal.setSucceeded(result, result.message);
    else if (cancelled || !ros::ok())
      goal.setCanceled(result, result.message);
    else
      goal.setAborted(result, result.message);
  }
}

// The request boundary of a goal (request_boundary.h): an unexpected error aborts it with the
// error's message; the worker goes on with the next goal.
TransferResult DncNode::runGoal(GoalHandle& goal, bool& cancelled)
{
  const auto& g = *goal.getGoal();
  try
  {
    return runReserved(
        g, [&goal](const TransferFeedback& f) { goal.publishFeedback(f); }, cancelled);
  }
  catch (...)
  {
    TransferResult result;
    result.message = boundary::failure(
        pnh_.resolveName("transfer") + " goal " + goal.getGoalID().id + " (" + g.direction + " " + g.file + ")",
        boundary::currentExceptionText());
    ROS_ERROR_STREAM(result.message);
    return result;
  }
}

namespace
{
// SendProgram and ReceiveProgram carry the same fields: one translation to and from the action.
template <class Request, class Response, class Run>
bool answerTransfer(const std::string& direction, const Request& request, Response& response, Run run)
{
  TransferGoal goal;
  goal.direction = direction;
  goal.file = request.file;
  goal.protocol = request.protocol;
  const TransferResult result = run(goal);
  response.success = result.success;
  response.message = result.message;
  response.bytes = result.bytes;
  response.blocks = result.blocks;
  response.retries = result.retries;
  return true;
}
}  // namespace

bool DncNode::onSend(SendProgram::Request& request, SendProgram::Response& response)
{
  return answerTransfer(TransferGoal::DIRECTION_SEND, request, response,
                        [this](const TransferGoal& goal) { return run(goal, nullptr); });
}

bool DncNode::onReceive(ReceiveProgram::Request& request, ReceiveProgram::Response& response)
{
  return answerTransfer(TransferGoal::DIRECTION_RECEIVE, request, response,
                        [this](const TransferGoal& goal) { return run(goal, nullptr); });
}
}  // namespace cnc_bridge
