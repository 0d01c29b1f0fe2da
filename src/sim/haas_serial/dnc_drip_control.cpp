// The simulated control of a drip-feed: buffer, execution rate, XON/XOFF marks, overrun counting.
#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <sstream>
#include <thread>
#include <vector>

#include "cnc_bridge/dnc/dnc_codes.h"
#include "dnc_sim.h"

namespace cnc_bridge
{
namespace sim
{
std::string DripControlStats::summary() const
{
  std::ostringstream out;
  out << "received " << received << " characters, xoff " << xoff_events << ", max after xoff " << max_after_xoff
      << ", xoff over allowance " << xoff_over_allowance << ", overruns " << overruns << ", overflow " << overflow
      << " (beyond the control's own lateness " << overflow_beyond_late << ", late " << late << ")"
      << ", parity errors " << parity_errors << ", program " << (program_complete ? "complete" : "incomplete")
      << (reset ? ", reset" : "");
  return out.str();
}

namespace
{
using Clock = std::chrono::steady_clock;

/// The characters in the control's buffer, in order, and the block the control reads from them
/// (DripControlHooks): executing a character moves it into the block; its end of block runs it.
class Execution
{
 public:
  explicit Execution(const DripControlHooks& hooks) : hooks_(hooks) {}

  void buffered(uint8_t c)
  {
    pending_.push_back(c);
    waiting_ = false;
  }

  void execute(size_t count)
  {
    for (size_t i = 0; i < count && !pending_.empty(); ++i)
    {
      read(pending_.front());
      pending_.pop_front();
    }
  }

  void executeAll() { execute(pending_.size()); }

  /// Reports, once, a buffer run empty in the middle of a program.
  void checkStarved()
  {
    if (pending_.empty() && inProgram() && !waiting_)
    {
      waiting_ = true;
      if (hooks_.waiting_for_data)
      {
        hooks_.waiting_for_data();
      }
    }
  }

 private:
  void read(uint8_t c)
  {
    if (c == '\n')
    {
      if (!block_.empty())
      {
        last_ = block_;
        block_.clear();
        if (hooks_.executed)
        {
          hooks_.executed(last_);
        }
      }
    }
    else if (c >= 0x20 && c < 0x7f)  // not CR, tape-feed NULs or DC codes
    {
      block_.push_back(static_cast<char>(c));
    }
  }

  bool inProgram() const { return !last_.empty() && last_ != "%"; }

  const DripControlHooks& hooks_;
  std::deque<uint8_t> pending_;
  std::string block_;  // read so far, its end of block not yet
  std::string last_;   // the block executed last
  bool waiting_ = false;
};
}  // namespace

DripControlStats runDripControl(Transport& link, const DripControlOptions& options, StopSignal& stop,
                                const std::function<void(const uint8_t*, size_t)>& sink, UartModel* line,
                                const DripControlHooks& hooks)
{
  DripControlStats stats;
  if (options.realtime)
  {
    sched_param param{};
    param.sched_priority = 10;
    pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);  // best effort: EPERM keeps the default
  }
  const auto code = [&](uint8_t c) { return options.seven_e1 ? dnc::withEvenParity(c) : c; };
  if (options.send_dc1_at_start)
  {
    link.writeByte(code(dnc::kDc1));
  }
  UartModel own_uart(options.line_cps);
  UartModel& uart = line != nullptr ? *line : own_uart;
  Execution execution(hooks);
  size_t buffered = 0;
  double credit = 0;  // characters the control could have executed but has not yet
  bool xoff = false;
  uint64_t after = 0;
  uint64_t event_late = 0;      // this XOFF event: characters taken past the mark before the XOFF
  uint64_t event_overflow = 0;  // this XOFF event: characters lost to a full buffer
  unsigned percents = 0;
  uint8_t last_char = 0;
  Clock::time_point completed_at;
  auto last = Clock::now();
  uint8_t buffer[256];
  std::vector<uint8_t> masked;
  masked.reserve(sizeof(buffer));

  const auto closeXoffEvent = [&]
  {
    stats.max_after_xoff = std::max(stats.max_after_xoff, after);
    if (after > options.allowance)
    {
      stats.overruns += after - options.allowance;
      ++stats.xoff_over_allowance;
    }
    stats.late += event_late;
    stats.overflow_beyond_late += event_overflow - std::min(event_overflow, event_late);
    xoff = false;
  };

  // Takes what one read returned into the buffer. Every character counts against the host if
  // the XOFF went out before the read; the XOFF is written after the batch that crossed the mark
  // (its characters were on the line before it).
  const auto take = [&](const uint8_t* data, size_t n)
  {
    masked.clear();
    bool crossed = false;
    for (size_t i = 0; i < n; ++i)
    {
      uint8_t c = data[i];
      if (options.seven_e1)
      {
        if ((c & 0x80) != 0 && dnc::withEvenParity(c) != c)
        {
          ++stats.parity_errors;
        }
        c = dnc::maskParity(c);
      }
      ++stats.received;
      masked.push_back(c);
      if (xoff)
      {
        ++after;
      }
      else if (crossed)
      {
        ++event_late;  // a control reacting at the character that crossed would have sent DC3 already
      }
      if (buffered >= options.buffer_size)
      {
        ++stats.overflow;
        if (xoff || crossed)
        {
          ++event_overflow;
        }
        else
        {
          ++stats.overflow_beyond_late;  // a buffer smaller than its high mark
        }
      }
      else
      {
        ++buffered;
        execution.buffered(c);
      }
      if (c == '%' && ++percents == 2)
      {
        stats.program_complete = true;
        completed_at = Clock::now();
      }
      last_char = c;
      if (!xoff && !crossed && buffered >= options.high_mark)
      {
        crossed = true;
        event_late = 0;
        event_overflow = 0;
      }
    }
    if (crossed)
    {
      link.writeByte(code(dnc::kDc3));
      xoff = true;
      after = 0;
      ++stats.xoff_events;
    }
    if (!masked.empty() && sink)
    {
      sink(masked.data(), masked.size());
    }
  };

  while (!stop.stopped())
  {
    if (hooks.reset && hooks.reset())
    {
      stats.reset = true;
      break;
    }
    const size_t wanted = uart.allowed(sizeof(buffer));
    const size_t n = link.read(buffer, wanted, uart.timeout());
    uart.took(n, wanted);
    const auto now = Clock::now();
    if (options.execution_cps <= 0)
    {
      execution.executeAll();
      buffered = 0;
    }
    else
    {
      credit += std::chrono::duration<double>(now - last).count() * options.execution_cps;
      const auto executed = static_cast<size_t>(std::min<double>(static_cast<double>(buffered), std::floor(credit)));
      buffered -= executed;
      execution.execute(executed);
      credit -= static_cast<double>(executed);
      if (buffered == 0)
      {
        credit = std::min(credit, 1.0);  // an idle control does not save up execution time
      }
    }
    last = now;
    take(buffer, n);
    execution.checkStarved();
    if (xoff && buffered <= options.low_mark)
    {
      closeXoffEvent();
      link.writeByte(code(dnc::kDc1));
    }
    // The program ends with the end of block after its closing '%' (LF, or CR alone: then the
    // line falls quiet): take that too, so the next program starts clean. An XOFF still standing
    // is answered first, once the buffer has drained to the low mark: a host that kept the DC3 as
    // the last word from the control would start its next program held, waiting for a DC1 that
    // a control with an empty buffer never has reason to send.
    if (stats.program_complete && options.stop_at_end && !xoff &&
        (last_char == '\n' || now - completed_at > std::chrono::milliseconds(50)))
    {
      break;
    }
  }
  if (xoff)
  {
    closeXoffEvent();
  }
  if (stats.program_complete)
  {
    execution.executeAll();
  }
  return stats;
}
}  // namespace sim
}  // namespace cnc_bridge
