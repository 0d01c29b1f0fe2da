// dnc_node's ~transfer action and its ~send_program / ~receive_program services (docs/dnc_node.md,
// "ROS interface"): the action is a SingleGoalActionServer, so a goal sent while a transfer runs
// is rejected with the reason and never preempts the running one. A goal is admitted only once it
// has reserved the port (a service call or a program request may hold it), and frees the port
// before its result goes out; a service call runs its transfer to the end.
#include "dnc_node.h"

namespace cnc_bridge
{
void DncNode::startTransferAction()
{
  action_ = std::make_unique<SingleGoalActionServer<TransferAction>>(
      pnh_, "transfer", [this](const TransferGoalConstPtr& goal) { executeGoal(*goal); },
      [](const TransferGoal& goal) { return goal.direction + " " + goal.file; });
  action_->setAdmission(
      [this](const std::string& id, const TransferGoal& g)
      {
        if (tryReserve("goal " + id + " (" + g.direction + " " + g.file + " by " +
                       (g.protocol.empty() ? default_protocol_ : g.protocol) + ")"))
          return std::string();
        return busyMessage();
      },
      [this] { gate_.release(); });
  action_->setCancelCallback([this] { cancelRunning(); });
  action_->start();
}

void DncNode::executeGoal(const TransferGoal& goal)
{
  TransferResult result;
  if (gate_.cancelFlag())
  {
    result.message = "cancelled before it started";
    action_->setPreempted(result, result.message);
    return;
  }
  bool cancelled = false;
  result = runReserved(
      goal, [this](const TransferFeedback& f) { action_->publishFeedback(f); }, cancelled);
  if (result.success)
    action_->setSucceeded(result, result.message);
  else if (cancelled || !ros::ok())
    action_->setPreempted(result, result.message);
  else
    action_->setAborted(result, result.message);
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
