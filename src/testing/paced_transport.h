// A Transport decorator that lets bytes out no faster than a real serial line would carry them.
// Simulators use it to behave like a 9600 or 115200 baud port on a pty (which has no baud rate),
// benchmarks to pace their writes to a real port. (bitsPerCharacter() is in serial_port.h.)
#pragma once

#include <chrono>

#include "cnc_bridge/transport/forwarding_transport.h"

namespace cnc_bridge
{
/// \brief Paces writes of an inner transport to \p characters_per_second. Reads pass through.
/// Not thread-safe beyond what the inner transport offers (interrupt() is forwarded).
class PacedTransport : public ForwardingTransport
{
 public:
  /// When a slice of about 2 ms of line time is handed to the inner transport.
  enum class Release
  {
    /// When the line would START sending it: keeps the average rate, for flow control and
    /// streaming (a drip-feed host, a simulated control's output).
    kWhenLineIsFree,
    /// When the line would have FINISHED sending it (its last stop bit): for stop-and-wait
    /// exchanges, where releasing at the start lets the last slice of every message arrive up to
    /// a slice early and a round trip look faster than the line allows.
    kWhenSent
  };

  /// \param inner the link to pace; must outlive this object.
  /// \param characters_per_second e.g. 11520 for 115200 baud 8N1 (10 bits per character).
  PacedTransport(Transport& inner, double characters_per_second, Release release = Release::kWhenLineIsFree);

  using ForwardingTransport::write;
  /// Writes in small slices, each released as \ref Release says.
  void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override;
  void drain() override;
  std::string describe() const override;

  double charactersPerSecond() const { return rate_; }

 private:
  using Clock = std::chrono::steady_clock;
  double rate_;
  Release release_;
  Clock::time_point line_free_at_;  // when the simulated line has sent everything written so far
};
}  // namespace cnc_bridge
