// SingleGoalActionServer: the one new-goal policy of every action that moves or cuts
// (docs/ROS_INTERFACE.md, "A second goal"). actionlib's SimpleActionServer preempts the running
// goal when a new one arrives, so a second client (a retry in orchestration code, a stray
// `rostopic pub`) could replace a cutting job without anyone cancelling it. This server is built
// on actionlib's ActionServer instead: while a goal runs, a new goal is rejected with a result
// that names the running goal and how to stop it; replacing a job takes an explicit cancel first.
// A node whose goals share a resource with other requests (dnc_node's serial port, also taken by
// its services) admits a goal only once it has reserved that resource (setAdmission()).
#pragma once

#include <actionlib/server/action_server.h>
#include <ros/ros.h>

#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "cnc_bridge/ros/request_boundary.h"

namespace cnc_bridge
{
/// \brief An action server that runs one goal at a time on its own thread and rejects a goal that
/// arrives while another runs (never preempts). The API follows SimpleActionServer's so that a
/// node's execute function reads the same. Thread-safe.
///
/// \tparam ActionSpec the generated action type (e.g. RunJobAction); its Result must have the
///         fields `bool success` and `string message`.
template <class ActionSpec>
class SingleGoalActionServer
{
 public:
  ACTION_DEFINITION(ActionSpec);
  using GoalHandle = actionlib::ServerGoalHandle<ActionSpec>;
  /// Runs one accepted goal to its end; must end it with setSucceeded/setAborted/setCanceled. An
  /// exception it throws aborts the goal with a message that names the goal and the error
  /// (request_boundary.h); the server then takes the next goal.
  using Execute = std::function<void(const GoalConstPtr&)>;
  /// Says in a few words what a goal does ("job part.nc"), for the rejection of another.
  using Describe = std::function<std::string(const Goal&)>;
  /// Takes what a goal needs before it is accepted (e.g. reserves a port shared with services):
  /// returns "" to accept the goal with \p goal_id, else the text it is rejected with.
  using Admit = std::function<std::string(const std::string& goal_id, const Goal& goal)>;

  /// \param pnh node handle the action lives under (the action is <pnh>/<name>).
  SingleGoalActionServer(ros::NodeHandle pnh, const std::string& name, Execute execute, Describe describe)
      : execute_(std::move(execute)),
        describe_(std::move(describe)),
        name_(pnh.resolveName(name)),
        server_(
            pnh, name, [this](GoalHandle goal) { onGoal(goal); }, [this](GoalHandle goal) { onCancel(goal); }, false)
  {
  }

  ~SingleGoalActionServer() { shutdown(); }

  void start()
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (started_)
        return;
      started_ = true;
    }
    worker_ = std::thread([this] { work(); });
    server_.start();
  }

  /// \brief Cancels the running goal and waits for its execute function to return.
  void shutdown()
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
      cancel_ = true;
    }
    cv_.notify_all();
    if (worker_.joinable())
      worker_.join();
  }

  /// \brief True once the running goal was cancelled, or the node is shutting down.
  bool isPreemptRequested() const
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return cancel_ || !ros::ok();
  }

  /// \brief Called (on the cancelling thread) when the running goal is cancelled, e.g. to
  /// interrupt a blocking read. Set before start().
  void setCancelCallback(std::function<void()> on_cancel) { on_cancel_ = std::move(on_cancel); }

  /// \brief Admits each goal by \p admit (called under the server's lock, so it must not call
  /// back into the server) instead of the rejection of a goal while another runs; \p release
  /// frees what it took once the admitted goal has ended, before its result goes out (a client
  /// may send its next goal as soon as it has the result). Set before start().
  void setAdmission(Admit admit, std::function<void()> release)
  {
    admit_ = std::move(admit);
    release_ = std::move(release);
  }

  void publishFeedback(const Feedback& feedback)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (current_)
      current_->publishFeedback(feedback);
  }

  void setSucceeded(const Result& result, const std::string& text = "") { finish(result, text, kSucceeded); }
  void setAborted(const Result& result, const std::string& text = "") { finish(result, text, kAborted); }
  /// \brief Ends the running goal as cancelled (PREEMPTED at a SimpleActionClient).
  void setPreempted(const Result& result, const std::string& text = "") { finish(result, text, kCanceled); }

  /// \brief The text a goal gets when it is rejected because \p running runs (exposed for tests).
  static std::string rejection(const std::string& action, const std::string& running_id,
                               const std::string& running_what)
  {
    return "rejected: " + action + " is running goal " + running_id + " (" + running_what +
           "); one goal at a time: cancel it first (" + action + "/cancel with its id, or cancel at its client), " +
           "then send this goal again";
  }

 private:
  enum Outcome
  {
    kSucceeded,
    kAborted,
    kCanceled
  };

  void onGoal(GoalHandle goal)
  {
    std::unique_lock<std::mutex> lock(mutex_);
    const std::string refusal = admission(goal);
    if (!refusal.empty())
    {
      Result result;
      result.success = false;
      result.message = refusal;
      lock.unlock();
      ROS_WARN_STREAM(name_ << ": goal " << goal.getGoalID().id << " " << result.message);
      goal.setRejected(result, result.message);
      return;
    }
    current_ = std::make_unique<GoalHandle>(goal);
    running_what_ = describe_ ? describe_(*goal.getGoal()) : std::string("a goal");
    cancel_ = false;
    pending_ = true;
    goal.setAccepted();
    lock.unlock();
    cv_.notify_all();
  }

  // Why \p goal is rejected, "" if it is accepted (mutex_ held): the node is stopping, admit_
  // refuses it, or another goal runs.
  std::string admission(const GoalHandle& goal)
  {
    if (stopping_)
      return "rejected: the node is shutting down";
    if (admit_)
    {
      const std::string refusal = admit_(goal.getGoalID().id, *goal.getGoal());
      if (!refusal.empty())
        return refusal;
      if (!current_)
        return "";
      if (release_)  // admitted while a goal runs: not for this server's one goal at a time
        release_();
    }
    return current_ ? rejection(name_, current_->getGoalID().id, running_what_) : "";
  }

  void onCancel(GoalHandle goal)
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!current_ || !(*current_ == goal))
        return;
      cancel_ = true;
    }
    if (on_cancel_)
      on_cancel_();
  }

  void work()
  {
    for (;;)
    {
      GoalConstPtr goal;
      std::unique_ptr<GoalHandle> running;  // the goal run here (current_ may be the next one by its end)
      std::string what;                     // "goal <id> (<what it does>)", for an error's message
      {
        std::unique_lock<std::mutex> lock(mutex_);
        cv_.wait(lock, [this] { return pending_ || stopping_; });
        if (!pending_)
          return;
        pending_ = false;
        goal = current_->getGoal();
        running = std::make_unique<GoalHandle>(*current_);
        what = name_ + " goal " + current_->getGoalID().id + " (" + running_what_ + ")";
        if (stopping_)
        {
          lock.unlock();
          Result result;
          result.message = "cancelled: the node is shutting down";
          finish(result, result.message, kCanceled);
          return;
        }
      }
      executeGuarded(goal, *running, what);
      Result result;
      result.message = "the goal ended without a result (a bug in the node)";
      finishIfRunning(*running, result, kAborted);  // no effect if execute_ ended it
    }
  }

  // The request boundary of a goal: an exception from execute_ aborts the goal with its message.
  void executeGuarded(const GoalConstPtr& goal, const GoalHandle& running, const std::string& what)
  {
    try
    {
      execute_(goal);
    }
    catch (...)
    {
      Result result;
      result.success = false;
      result.message = boundary::failure(what, boundary::currentExceptionText());
      ROS_ERROR_STREAM(result.message);
      finishIfRunning(running, result, kAborted);  // no effect if execute_ ended the goal before it threw
    }
  }

  // Ends \p running unless it has ended: a client that had its result may have sent the next goal,
  // which is current_ now and must not be ended here.
  void finishIfRunning(const GoalHandle& running, const Result& result, Outcome outcome)
  {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!current_ || !(*current_ == running))
        return;
    }
    finish(result, result.message, outcome);
  }

  // Frees the server before the result goes out: a client may send its next goal as soon as it
  // has the result of this one.
  void finish(const Result& result, const std::string& text, Outcome outcome)
  {
    std::unique_ptr<GoalHandle> goal;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      goal.swap(current_);
    }
    if (!goal)
      return;
    if (release_)
      release_();
    switch (outcome)
    {
      case kSucceeded:
        goal->setSucceeded(result, text);
        break;
      case kAborted:
        goal->setAborted(result, text);
        break;
      case kCanceled:
        goal->setCanceled(result, text);
        break;
    }
  }

  Execute execute_;
  Describe describe_;
  std::function<void()> on_cancel_;
  Admit admit_;
  std::function<void()> release_;
  const std::string name_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::unique_ptr<GoalHandle> current_;  ///< the goal accepted and not yet ended
  std::string running_what_;
  bool pending_ = false;  ///< current_ accepted, not yet picked up by the worker
  bool cancel_ = false;
  bool stopping_ = false;
  bool started_ = false;
  std::thread worker_;
  actionlib::ActionServer<ActionSpec> server_;  ///< last: destroyed first, no callback into a dead member
};
}  // namespace cnc_bridge
