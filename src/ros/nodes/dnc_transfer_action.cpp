// dnc_node's ~transfer action and its ~send_program / ~receive_program services (docs/dnc_node.md,
// "ROS interface"): the action is a SingleGoalActionServer, so a goal sent while a transfer runs
// is rejected with the reason and never preempts the running one. A goal is admitted only once it
// has reserved the port (a service call or a program request may hold it), and frees the port
// before its result goes out; a service call runs its transfer to the end. The transfers are the
// session's (dnc::TransferSession); this file translates goals, feedback and results.
#include "dnc_node.h"

namespace cnc_bridge
{
namespace
{
dnc::TransferRequest requestOf(const TransferGoal& goal)
{
  dnc::TransferRequest request;
  request.direction = goal.direction;
  request.protocol = goal.protocol;
  request.file = goal.file;
  request.start_line = goal.start_line;
  request.start_block = goal.start_block;
  request.restart_preamble = goal.restart_preamble;
  return request;
}

TransferFeedback feedbackOf(const dnc::TransferProgress& progress)
{
  TransferFeedback f;
  f.bytes = progress.bytes;
  f.total = progress.total;
  f.block = progress.block;
  f.retries = progress.retries;
  f.line = progress.line;
  f.block_number = progress.block_number;
  f.percent = progress.percent;
  f.held = progress.held;
  f.paused = progress.paused;
  return f;
}

TransferResult resultOf(const dnc::TransferOutcome& outcome)
{
  TransferResult result;
  result.success = outcome.success;
  result.message = outcome.message;
  result.bytes = outcome.bytes;
  result.blocks = outcome.blocks;
  result.retries = outcome.retries;
  result.stopped_at_line = outcome.stopped_at_line;
  result.stopped_at_block = outcome.stopped_at_block;
  return result;
}
}  // namespace

void DncNode::startTransferAction()
{
  action_ = std::make_unique<SingleGoalActionServer<TransferAction>>(
      pnh_, "transfer", [this](const TransferGoalConstPtr& goal) { executeGoal(*goal); },
      [](const TransferGoal& goal) { return goal.direction + " " + goal.file; });
  action_->setAdmission(
      [this](const std::string& id, const TransferGoal& g)
      {
        if (session_->tryReserve("goal " + id + " (" + g.direction + " " + g.file + " by " +
                                 (g.protocol.empty() ? session_->defaultProtocol() : g.protocol) + ")"))
          return std::string();
        return session_->busyMessage();
      },
      [this] { session_->release(); });
  action_->setCancelCallback([this] { session_->cancelRunning(); });
  action_->start();
}

void DncNode::executeGoal(const TransferGoal& goal)
{
  TransferResult result;
  if (session_->cancelRequested())
  {
    result.message = "cancelled before it started";
    action_->setPreempted(result, result.message);
    return;
  }
  const dnc::TransferOutcome outcome = session_->runReserved(
      requestOf(goal), [this](const dnc::TransferProgress& p) { action_->publishFeedback(feedbackOf(p)); });
  result = resultOf(outcome);
  if (result.success)
    action_->setSucceeded(result, result.message);
  else if (outcome.cancelled || !ros::ok())
    action_->setPreempted(result, result.message);
  else
    action_->setAborted(result, result.message);
}

namespace
{
// SendProgram and ReceiveProgram carry the same fields: one translation to and from the session.
template <class Request, class Response>
bool answerTransfer(dnc::TransferSession& session, const std::string& direction, const Request& request,
                    Response& response)
{
  dnc::TransferRequest transfer;
  transfer.direction = direction;
  transfer.file = request.file;
  transfer.protocol = request.protocol;
  const dnc::TransferOutcome outcome = session.run(transfer, nullptr);
  response.success = outcome.success;
  response.message = outcome.message;
  response.bytes = outcome.bytes;
  response.blocks = outcome.blocks;
  response.retries = outcome.retries;
  return true;
}
}  // namespace

bool DncNode::onSend(SendProgram::Request& request, SendProgram::Response& response)
{
  return answerTransfer(*session_, TransferGoal::DIRECTION_SEND, request, response);
}

bool DncNode::onReceive(ReceiveProgram::Request& request, ReceiveProgram::Response& response)
{
  return answerTransfer(*session_, TransferGoal::DIRECTION_RECEIVE, request, response);
}
}  // namespace cnc_bridge
