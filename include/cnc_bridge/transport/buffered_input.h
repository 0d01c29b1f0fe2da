// The input side of a protocol session, read in bulk: each read() on the link takes whatever has
// arrived (up to the buffer's size, e.g. one whole XModem packet), and the session then takes it
// byte by byte or packet by packet from memory. A packet that arrives in one piece costs one read
// instead of one per byte (or one for its first byte and one for the rest).
//
// Bytes in the buffer count as received input: purge() and discard() drop them together with what
// the link still holds, so the protocol sees exactly what it would with unbuffered reads.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <vector>

#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
/// \brief Buffered reads over a Transport. Not thread-safe (the session's thread only); the
/// link's interrupt() still stops a read in progress.
class BufferedInput
{
 public:
  /// \param capacity the most one read() asks the link for.
  BufferedInput(Transport& link, size_t capacity) : link_(link), buffer_(std::max<size_t>(capacity, 1)) {}

  /// \returns the next byte, or -1 if none arrived within \p timeout.
  int readByte(Milliseconds timeout)
  {
    if (empty() && !fill(timeout))
      return -1;
    return buffer_[begin_++];
  }

  /// \brief Reads exactly \p size bytes, each within \p per_byte_timeout of the previous one.
  /// \returns the number read before a timeout (== size on success).
  size_t readExactly(uint8_t* out, size_t size, Milliseconds per_byte_timeout)
  {
    size_t done = 0;
    while (done < size)
    {
      if (empty() && !fill(per_byte_timeout))
        break;
      const size_t n = std::min(size - done, end_ - begin_);
      std::memcpy(out + done, buffer_.data() + begin_, n);
      begin_ += n;
      done += n;
    }
    return done;
  }

  /// \brief Drops buffered bytes, then reads and drops until \p quiet passes with nothing received.
  /// \param limit gives up after this long in total (a babbling peer cannot hold us forever).
  /// \returns the number of bytes dropped.
  size_t purge(Milliseconds quiet, Milliseconds limit = Milliseconds(10000))
  {
    const size_t dropped = end_ - begin_;
    begin_ = end_ = 0;
    return dropped + link_.purge(quiet, limit);
  }

  /// \brief Drops buffered bytes and the input the link has queued (Transport::discardInput()).
  void discard()
  {
    begin_ = end_ = 0;
    link_.discardInput();
  }

  /// \brief Bytes read from the link but not yet taken.
  size_t buffered() const { return end_ - begin_; }

 private:
  bool empty() const { return begin_ == end_; }

  /// Refills the empty buffer with one read. \returns false on timeout.
  bool fill(Milliseconds timeout)
  {
    begin_ = 0;
    end_ = link_.read(buffer_.data(), buffer_.size(), timeout);
    return end_ > 0;
  }

  Transport& link_;
  std::vector<uint8_t> buffer_;
  size_t begin_ = 0;
  size_t end_ = 0;
};
}  // namespace cnc_bridge
