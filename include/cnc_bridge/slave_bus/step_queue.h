// The steps waiting for the bus. Every step is one frame with a payload slot per slave, so
// commands published together (x, y, then the tool) should travel in one frame: a command joins
// the last queued step of commands while its slot there is free and the step has not left, and a
// step of commands leaves a short delay after its first command so that the others can join.
// While the link is down the queue is closed: nothing waits to move the machine when it returns.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <vector>

#include "cnc_bridge/slave_bus/array_protocol.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief A bounded queue of steps between the threads that publish commands and the one that
/// sends frames. Thread-safe.
class StepQueue
{
 public:
  /// \param bus_size payload slots of every step.
  /// \param max_steps steps that may wait; more are refused (the caller counts and reports them).
  /// \param command_delay how long a step of commands waits for more commands after its first.
  StepQueue(size_t bus_size, size_t max_steps, Milliseconds command_delay);

  /// \brief Queues an explicit frame as it is: it never merges, and commands after it do not join
  /// steps before it. \returns false when the queue is full or closed (nothing queued).
  bool pushFrame(StepPayloads payloads);
  /// \brief Puts \p payload in slot \p slot (address - 1) of the last queued step of commands if
  /// that slot is free there, else in a new step (a second command to the same slave waits for
  /// the following step: none is lost). \returns false when the queue is closed, or when a new step
  /// is needed and the queue is full (nothing queued).
  bool pushCommand(size_t slot, std::vector<uint8_t> payload);

  /// \brief Takes the next step that may leave, waiting up to \p idle for one (woken at once by a
  /// push and by stop()). \returns false if none may leave yet, or after stop().
  bool take(StepPayloads& step, Milliseconds idle);
  /// \brief Ends every take(), now and later.
  void stop();
  bool stopped() const;

  /// \brief Drops every waiting step and refuses pushes until open(): for a link that went down,
  /// whose steps must not move the machine when it comes back, long after they were asked for.
  /// \returns the steps dropped.
  size_t close();
  /// \brief Accepts pushes again (the link is up). A new queue is open.
  void open();
  /// \brief false between close() and open(): pushes are refused.
  bool isOpen() const;

  size_t size() const;

 private:
  struct Step
  {
    StepPayloads payloads;
    bool from_commands = false;
    std::chrono::steady_clock::time_point first_command;
  };

  bool pushLocked(Step step);

  const size_t bus_size_;
  const size_t max_steps_;
  const Milliseconds command_delay_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<Step> steps_;
  bool stopped_ = false;
  bool open_ = true;
};
}  // namespace slave_bus
}  // namespace cnc_bridge
