// Steps waiting for the bus (see step_queue.h).
#include "cnc_bridge/slave_bus/step_queue.h"

#include <algorithm>

namespace cnc_bridge
{
namespace slave_bus
{
StepQueue::StepQueue(size_t bus_size, size_t max_steps, Milliseconds command_delay)
    : bus_size_(bus_size), max_steps_(std::max<size_t>(1, max_steps)), command_delay_(command_delay)
{
}

bool StepQueue::pushFrame(StepPayloads payloads)
{
  payloads.resize(bus_size_);
  std::lock_guard<std::mutex> lock(mutex_);
  return pushLocked(Step{std::move(payloads), false, {}});
}

bool StepQueue::pushCommand(size_t slot, std::vector<uint8_t> payload)
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (!open_)
  {
    return false;
  }
  // Only the last step can take it: joining an earlier one would reorder commands across an
  // explicit frame or overtake a command to the same slave.
  if (!steps_.empty() && steps_.back().from_commands && steps_.back().payloads.at(slot).empty())
  {
    steps_.back().payloads[slot] = std::move(payload);
    return true;
  }
  Step step{StepPayloads(bus_size_), true, std::chrono::steady_clock::now()};
  step.payloads.at(slot) = std::move(payload);
  return pushLocked(std::move(step));
}

bool StepQueue::pushLocked(Step step)
{
  if (!open_ || steps_.size() >= max_steps_)
  {
    return false;
  }
  steps_.push_back(std::move(step));
  changed_.notify_all();
  return true;
}

bool StepQueue::take(StepPayloads& step, Milliseconds idle)
{
  std::unique_lock<std::mutex> lock(mutex_);
  const auto deadline = std::chrono::steady_clock::now() + idle;
  for (;;)
  {
    if (stopped_)
    {
      return false;
    }
    auto wait_until = deadline;
    if (!steps_.empty())
    {
      Step& front = steps_.front();
      // A step of commands may still gain commands until command_delay has passed, unless
      // another step already waits behind it (then nothing more can join it).
      const auto leaves_at = front.first_command + command_delay_;
      if (!front.from_commands || steps_.size() > 1 || std::chrono::steady_clock::now() >= leaves_at)
      {
        step = std::move(front.payloads);
        steps_.pop_front();
        return true;
      }
      wait_until = std::min(deadline, leaves_at);
    }
    if (std::chrono::steady_clock::now() >= deadline)
    {
      return false;
    }
    changed_.wait_until(lock, wait_until);
  }
}

void StepQueue::stop()
{
  std::lock_guard<std::mutex> lock(mutex_);
  stopped_ = true;
  changed_.notify_all();
}

bool StepQueue::stopped() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return stopped_;
}

size_t StepQueue::close()
{
  std::lock_guard<std::mutex> lock(mutex_);
  open_ = false;
  const size_t dropped = steps_.size();
  steps_.clear();
  return dropped;
}

void StepQueue::open()
{
  std::lock_guard<std::mutex> lock(mutex_);
  open_ = true;
}

bool StepQueue::isOpen() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return open_;
}

size_t StepQueue::size() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return steps_.size();
}
}  // namespace slave_bus
}  // namespace cnc_bridge
