// A scripted Transport for unit tests: the test feeds the bytes "the device" sends, sees every
// byte the session wrote, and can answer writes from a callback. Reads wait on a condition
// variable, never on sleeps, so tests are fast and deterministic.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
/// \brief In-memory Transport. All methods are thread-safe.
class FakeTransport : public Transport
{
 public:
  using WriteHook = std::function<void(FakeTransport&, const std::vector<uint8_t>&)>;

  explicit FakeTransport(std::string name = "fake") : name_(std::move(name)) {}

  // Test side.
  /// \brief Queues bytes for the session to read.
  void feed(const std::vector<uint8_t>& bytes);
  void feed(const std::string& text);
  /// \brief Called (outside the lock) after every write with the bytes just written.
  void onWrite(WriteHook hook);
  /// \brief Everything the session wrote so far.
  std::vector<uint8_t> written() const;
  void clearWritten();
  /// \brief The peer goes away: reads throw LinkError once queued input is consumed.
  void disconnect();
  /// \brief At most this many bytes per read() (0 = no limit), to exercise partial reads.
  void setMaxReadChunk(size_t bytes);
  /// \brief Waits until the session has written at least \p count bytes in total.
  bool waitForWritten(size_t count, Milliseconds timeout) const;

  // Transport.
  using Transport::write;
  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override;
  void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override;
  void discardInput() override;
  void interrupt() override;
  void close() override;
  bool isOpen() const override;
  std::string describe() const override { return name_; }

 private:
  std::string name_;
  mutable std::mutex mutex_;
  mutable std::condition_variable changed_;
  std::deque<uint8_t> input_;
  std::vector<uint8_t> written_;
  WriteHook hook_;
  size_t max_chunk_ = 0;
  bool disconnected_ = false;
  bool closed_ = false;
  bool interrupted_ = false;
};
}  // namespace cnc_bridge
