// The simulated board's serial debug port: the lines the board prints (board.h, DebugMessage),
// written with CR LF by a thread of their own, so that a port nobody reads (its buffer full) never
// holds up the board: what does not fit in the queue is dropped and counted, as a UART's output
// is lost when nobody listens.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>

#include "cnc_bridge/transport/transport.h"
#include "sim/ethernut/board.h"

namespace cnc_bridge
{
namespace ethernut
{
/// \brief Prints debug lines on \p port (a pty's master in sim_ethernut). Thread-safe.
class DebugPort
{
 public:
  /// \param port must outlive this object.
  /// \param max_queued lines waiting to be written; more are dropped.
  explicit DebugPort(Transport& port, size_t max_queued = 256);
  ~DebugPort();
  DebugPort(const DebugPort&) = delete;
  DebugPort& operator=(const DebugPort&) = delete;

  /// \brief Queues debugLine(\p message) followed by CR LF; never blocks.
  void print(const DebugMessage& message);
  uint64_t dropped() const;

 private:
  void run();

  Transport& port_;
  size_t max_queued_;
  mutable std::mutex mutex_;
  std::condition_variable queued_;
  std::deque<std::string> lines_;
  uint64_t dropped_ = 0;
  bool stopping_ = false;
  std::thread writer_;
};
}  // namespace ethernut
}  // namespace cnc_bridge
