// PacedTransport: sleeps until the simulated line is free, in slices of a few milliseconds, so the
// receiver sees a steady trickle as from a UART rather than bursts.
#include "testing/paced_transport.h"

#include <algorithm>
#include <sstream>
#include <thread>

namespace cnc_bridge
{
PacedTransport::PacedTransport(Transport& inner, double characters_per_second, Release release)
    : ForwardingTransport(inner), rate_(characters_per_second), release_(release), line_free_at_(Clock::now())
{
}

void PacedTransport::write(const uint8_t* data, size_t size, Milliseconds timeout)
{
  // About 2 ms of line time per slice: fine-grained enough to look like a UART, coarse enough
  // that the scheduler's wake-up jitter stays small against it.
  const size_t slice = std::max<size_t>(1, static_cast<size_t>(rate_ * 0.002));
  const auto per_char = std::chrono::duration<double>(1.0 / rate_);
  size_t done = 0;
  while (done < size)
  {
    const size_t n = std::min(slice, size - done);
    const auto now = Clock::now();
    if (line_free_at_ < now)
    {
      line_free_at_ = now;  // the line was idle: no credit for the time it sat unused
    }
    const auto line_starts_slice = line_free_at_;
    line_free_at_ += std::chrono::duration_cast<Clock::duration>(per_char * static_cast<double>(n));
    std::this_thread::sleep_until(release_ == Release::kWhenSent ? line_free_at_ : line_starts_slice);
    inner_.write(data + done, n, timeout);
    done += n;
  }
}

void PacedTransport::drain()
{
  std::this_thread::sleep_until(line_free_at_);
  inner_.drain();
}

std::string PacedTransport::describe() const
{
  std::ostringstream out;
  out << inner_.describe() << " paced to " << rate_ << " char/s";
  return out.str();
}
}  // namespace cnc_bridge
