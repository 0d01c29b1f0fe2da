// The byte-stream link every protocol session runs over: a serial port, a TCP connection, a pty
// or a scripted fake. Sessions take a Transport& so that tests can hand them any of these.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace cnc_bridge
{
/// Connection state of a link, mirrored in cnc_bridge/MachineState.link.
enum class LinkState
{
  kDown,
  kConnecting,
  kUp
};
const char* toString(LinkState state);

using Milliseconds = std::chrono::milliseconds;
constexpr Milliseconds kWaitForever = Milliseconds::max();

/// \brief A bidirectional byte stream with timeouts.
///
/// One thread reads and writes; interrupt() may be called from any thread. Implementations
/// throw LinkError (with describe() in the message) when the link fails or the peer goes away.
class Transport
{
 public:
  virtual ~Transport() = default;

  /// \brief Reads what is available, up to \p size bytes, waiting at most \p timeout for the first.
  /// \returns the number of bytes read; 0 when the timeout expired with nothing to read.
  /// \throws LinkError if the link is closed or broken; CancelledError after interrupt().
  virtual size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) = 0;

  /// \brief Writes all \p size bytes, waiting at most \p timeout for the link to take them.
  /// \throws TimeoutError if the link did not take them in time (flow control held it),
  ///         LinkError, CancelledError.
  virtual void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) = 0;

  /// \brief Waits until everything written has left the host (tcdrain on a serial port).
  virtual void drain() {}

  /// \brief Bytes written but not yet sent on the wire (serial output queue); 0 if unknown.
  virtual size_t pendingOutput() const { return 0; }

  /// \brief Discards input received but not yet read.
  virtual void discardInput() = 0;

  /// \brief Makes the blocking read or write in progress (or the next one) throw CancelledError.
  /// Thread-safe.
  virtual void interrupt() = 0;

  virtual void close() = 0;
  virtual bool isOpen() const = 0;

  /// \brief Where this link goes, for messages: "/dev/ttyUSB0@115200", "10.0.0.5:6666".
  virtual std::string describe() const = 0;

  // Conveniences built on the primitives above.

  /// \returns the next byte, or -1 if none arrived within \p timeout.
  int readByte(Milliseconds timeout);
  /// \brief Reads exactly \p size bytes, each within \p per_byte_timeout of the previous one.
  /// \returns the number read before a timeout (== size on success).
  size_t readExactly(uint8_t* buffer, size_t size, Milliseconds per_byte_timeout);
  void write(const std::string& text, Milliseconds timeout = kWaitForever);
  void write(const std::vector<uint8_t>& bytes, Milliseconds timeout = kWaitForever);
  void writeByte(uint8_t byte, Milliseconds timeout = kWaitForever);
  /// \brief Reads and drops bytes until \p quiet passes with nothing received (XModem "purge").
  /// \param limit gives up after this long in total, so a babbling peer cannot hold us forever.
  /// \returns the number of bytes dropped.
  size_t purge(Milliseconds quiet, Milliseconds limit = Milliseconds(10000));
};
}  // namespace cnc_bridge
