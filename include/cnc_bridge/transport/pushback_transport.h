// A transport whose bytes already read can be put back, so that the protocol session a byte
// starts sees it: a listener that waits for a control to begin an XModem punch reads the SOH
// itself, then hands the line, SOH first, to the XModem receiver.
#pragma once

#include <cstdint>
#include <deque>

#include "cnc_bridge/transport/forwarding_transport.h"

namespace cnc_bridge
{
/// \brief Returns the bytes put back with unread() before reading the wrapped transport. Not
/// thread-safe (one reader), except interrupt() as the wrapped transport's.
class PushbackTransport : public ForwardingTransport
{
 public:
  explicit PushbackTransport(Transport& inner) : ForwardingTransport(inner) {}
  /// \brief \p byte is the next byte read.
  void unread(uint8_t byte) { pushed_.push_front(byte); }

  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override
  {
    if (!pushed_.empty() && size > 0)
    {
      size_t n = 0;
      while (n < size && !pushed_.empty())
      {
        buffer[n++] = pushed_.front();
        pushed_.pop_front();
      }
      return n;
    }
    return inner_.read(buffer, size, timeout);
  }
  void discardInput() override
  {
    pushed_.clear();
    inner_.discardInput();
  }

 private:
  std::deque<uint8_t> pushed_;
};
}  // namespace cnc_bridge
