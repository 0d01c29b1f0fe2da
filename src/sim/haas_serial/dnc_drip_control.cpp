// The simulated control of a drip-feed: buffer, execution rate, XON/XOFF marks, overrun counting.
#include <pthread.h>
#include <sched.h>

#include <cmath>
#include <sstream>
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
      << ", max in flight at xoff " << max_in_flight << ", overruns " << overruns << ", overflow " << overflow
      << ", parity errors " << parity_errors << ", program " << (program_complete ? "complete" : "incomplete");
  return out.str();
}

DripControlStats runDripControl(Transport& link, const DripControlOptions& options, StopSignal& stop,
                                const std::function<void(const uint8_t*, size_t)>& sink)
{
  using Clock = std::chrono::steady_clock;
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
  size_t buffered = 0;
  double credit = 0;  // characters the control could have executed but has not yet
  bool xoff = false;
  uint64_t after = 0;
  uint64_t in_flight = 0;
  unsigned percents = 0;
  auto last = Clock::now();
  uint8_t buffer[256];
  std::vector<uint8_t> masked;
  masked.reserve(sizeof(buffer));

  const auto closeXoffEvent = [&]
  {
    stats.max_after_xoff = std::max(stats.max_after_xoff, after);
    stats.max_in_flight = std::max(stats.max_in_flight, in_flight);
    stats.overruns += after > options.allowance ? after - options.allowance : 0;
    xoff = false;
  };

  // Takes received characters into the buffer. \p sent_after_xoff: they were read after the XOFF
  // went out and after what was queued at that moment had been taken, so the host sent them after
  // it could have seen the XOFF.
  bool crossed = false;
  const auto take = [&](const uint8_t* data, size_t n, bool sent_after_xoff)
  {
    masked.clear();
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
        ++(sent_after_xoff ? after : in_flight);
      }
      if (buffered >= options.buffer_size)
      {
        ++stats.overflow;
      }
      else
      {
        ++buffered;
      }
      if (c == '%' && ++percents == 2)
      {
        stats.program_complete = true;
      }
      if (!xoff && buffered >= options.high_mark)
      {
        link.writeByte(code(dnc::kDc3));
        xoff = true;
        crossed = true;
        after = 0;
        in_flight = 0;
        ++stats.xoff_events;
      }
    }
    if (!masked.empty() && sink)
    {
      sink(masked.data(), masked.size());
    }
  };

  while (!stop.stopped())
  {
    // 1 ms reads: execution proceeds (and XON goes out) even while the host is silent.
    const size_t n = link.read(buffer, sizeof(buffer), Milliseconds(1));
    const auto now = Clock::now();
    if (options.execution_cps <= 0)
    {
      buffered = 0;
    }
    else
    {
      credit += std::chrono::duration<double>(now - last).count() * options.execution_cps;
      const auto executed = static_cast<size_t>(std::min<double>(static_cast<double>(buffered), std::floor(credit)));
      buffered -= executed;
      credit -= static_cast<double>(executed);
      if (buffered == 0)
      {
        credit = std::min(credit, 1.0);  // an idle control does not save up execution time
      }
    }
    last = now;
    crossed = false;
    take(buffer, n, xoff);
    if (crossed)
    {
      // A UART control reacts within a character time; this one may have been descheduled while
      // the pty filled. What is queued now was sent before the XOFF: take it as in flight, so
      // that `after` counts only what the host sent once it could have seen the XOFF.
      for (size_t queued = 1; queued > 0;)
      {
        queued = link.read(buffer, sizeof(buffer), Milliseconds(0));
        take(buffer, queued, false);
      }
    }
    if (xoff && buffered <= options.low_mark)
    {
      closeXoffEvent();
      link.writeByte(code(dnc::kDc1));
    }
    if (stats.program_complete && options.stop_at_end)
    {
      break;
    }
  }
  if (xoff)
  {
    closeXoffEvent();
  }
  return stats;
}
}  // namespace sim
}  // namespace cnc_bridge
