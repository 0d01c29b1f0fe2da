// A Transport decorator that hands each byte to the link no sooner than a UART would have finished
// sending it, so that a round trip over a pty (which has no baud rate) takes at least what the
// same exchange takes on a real serial line. sim_slave_bus --baud and bench_slave_bus use it.
//
// PacedTransport (transport/) is right for flow control: it keeps the average rate and lets each
// ~2 ms slice out when the line would START sending it. For a stop-and-wait exchange that lets the
// last slice of every message arrive up to one slice early, so a step looked faster than the line
// allows (the slave bus benchmark measured 1.10 of the line-rate bound). This one lets a slice out
// when the line would FINISH it: the receiver never sees a byte before its stop bit.
#pragma once

#include <algorithm>
#include <chrono>
#include <sstream>
#include <string>
#include <thread>

#include "cnc_bridge/transport/forwarding_transport.h"

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief Delays writes of an inner transport to the time a UART at \p characters_per_second
/// would have finished them. Reads pass through. Not thread-safe beyond the inner transport.
class LineTimedTransport : public ForwardingTransport
{
 public:
  /// \param inner the link; must outlive this object.
  /// \param characters_per_second e.g. 11520 for 115200 baud 8N1 (10 bits per character).
  LineTimedTransport(Transport& inner, double characters_per_second)
      : ForwardingTransport(inner), rate_(characters_per_second), line_free_at_(Clock::now())
  {
  }

  using ForwardingTransport::write;
  /// Writes in slices of about 2 ms of line time; each leaves when the line has sent its last byte.
  void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override
  {
    const size_t slice = std::max<size_t>(1, static_cast<size_t>(rate_ * 0.002));
    const std::chrono::duration<double> per_char(1.0 / rate_);
    size_t done = 0;
    while (done < size)
    {
      const size_t n = std::min(slice, size - done);
      const auto now = Clock::now();
      if (line_free_at_ < now)
      {
        line_free_at_ = now;  // the line was idle: it starts sending now
      }
      line_free_at_ += std::chrono::duration_cast<Clock::duration>(per_char * static_cast<double>(n));
      std::this_thread::sleep_until(line_free_at_);  // the slice's last stop bit
      inner_.write(data + done, n, timeout);
      done += n;
    }
  }

  std::string describe() const override
  {
    std::ostringstream out;
    out << inner_.describe() << " timed as a line of " << rate_ << " char/s";
    return out.str();
  }

  double charactersPerSecond() const { return rate_; }

 private:
  using Clock = std::chrono::steady_clock;
  double rate_;
  Clock::time_point line_free_at_;  // when the simulated line has sent everything written so far
};
}  // namespace slave_bus
}  // namespace cnc_bridge
