// SimulatedLine: a serial line in memory, each character one character time on the wire.
#include "testing/simulated_line.h"

#include <algorithm>
#include <thread>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace sim
{
SimulatedLine::SimulatedLine(double cps)
    : char_time_(std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / cps))),
      host_(*this, to_control_, to_host_, "simulated line (host)"),
      control_(*this, to_host_, to_control_, "simulated line (control)")
{
}

size_t SimulatedLine::End::read(uint8_t* buffer, size_t size, Milliseconds timeout)
{
  const auto now = Clock::now();
  const auto deadline = timeout >= Milliseconds(1000LL * 3600 * 24 * 365) ? Clock::time_point::max() : now + timeout;
  std::unique_lock<std::mutex> lock(line_.mutex_);
  for (;;)
  {
    if (interrupted_.exchange(false))
    {
      throw CancelledError(name_ + ": interrupted");
    }
    const auto t = Clock::now();
    size_t n = 0;
    last_read_carried_.clear();
    while (n < size && !in_.queue.empty() && in_.queue.front().second <= t)
    {
      buffer[n++] = in_.queue.front().first;
      last_read_carried_.push_back(in_.queue.front().second);
      in_.queue.pop_front();
    }
    if (n > 0 || t >= deadline || size == 0)
    {
      return n;
    }
    // Wake when the next character has been carried, or something is written, or the deadline.
    auto wake = deadline;
    if (!in_.queue.empty())
    {
      wake = std::min(wake, in_.queue.front().second);
    }
    if (wake == Clock::time_point::max())
    {
      line_.changed_.wait(lock);
    }
    else
    {
      line_.changed_.wait_until(lock, wake);
    }
  }
}

void SimulatedLine::End::write(const uint8_t* data, size_t size, Milliseconds /*timeout*/)
{
  std::lock_guard<std::mutex> lock(line_.mutex_);
  const auto now = Clock::now();
  for (size_t i = 0; i < size; ++i)
  {
    // A line that sat idle starts carrying now; a busy one after its last character.
    last_write_starts_ = std::max(out_.line_free, now);
    out_.line_free = last_write_starts_ + line_.char_time_;
    out_.queue.emplace_back(data[i], out_.line_free);
  }
  line_.changed_.notify_all();
}

SimulatedLine::End::TimePoint SimulatedLine::End::lastWriteStartsAt() const
{
  std::lock_guard<std::mutex> lock(line_.mutex_);
  return last_write_starts_;
}

void SimulatedLine::End::drain()
{
  Clock::time_point until;
  {
    std::lock_guard<std::mutex> lock(line_.mutex_);
    until = out_.line_free;
  }
  std::this_thread::sleep_until(until);
}

size_t SimulatedLine::End::pendingOutput() const
{
  std::lock_guard<std::mutex> lock(line_.mutex_);
  const auto now = Clock::now();
  return static_cast<size_t>(
      std::count_if(out_.queue.begin(), out_.queue.end(), [&](const auto& c) { return c.second > now; }));
}

void SimulatedLine::End::discardInput()
{
  std::lock_guard<std::mutex> lock(line_.mutex_);
  const auto now = Clock::now();
  while (!in_.queue.empty() && in_.queue.front().second <= now)
  {
    in_.queue.pop_front();
  }
}

void SimulatedLine::End::interrupt()
{
  std::lock_guard<std::mutex> lock(line_.mutex_);
  interrupted_ = true;
  line_.changed_.notify_all();
}
}  // namespace sim
}  // namespace cnc_bridge
