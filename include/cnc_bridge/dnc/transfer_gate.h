// One transfer at a time on a serial port, and the idle listener that steps aside for it
// (docs/dnc_node.md, "Program requests from the control"): a transfer (a service call, an action
// goal, a program request being served) reserves the port or is refused with what holds it (the
// transfer core's TransferSlot, programs/transfer_core.h); the listener reads the port only while
// nothing is reserved, and leaves it (within its poll period) when a transfer asks for it.
#pragma once

#include <atomic>
#include <chrono>
#include <string>

#include "cnc_bridge/programs/transfer_core.h"

namespace cnc_bridge::dnc
{
/// \brief Thread-safe.
class TransferGate : public programs::TransferSlot
{
 public:
  /// \brief Reserves the port for a transfer, \p what (named in the refusal of another); tells the
  /// listener to leave. A cancel of the previous transfer does not carry over.
  /// \returns false if the port is reserved already.
  bool tryReserve(const std::string& what);
  /// \brief As tryReserve(), for the listener that found a punch starting: it does not tell itself
  /// to leave. \param running set to what holds the port when it is refused.
  bool tryReserveForPunch(const std::string& what, std::string& running);

  /// \brief The listener: waits until the port is free, then marks it as listening.
  /// \returns false when the listener is to stop for good.
  bool waitToListen();
  /// \brief The listener has left the port.
  void leftPort();
  /// \brief A transfer that has reserved the port waits until the listener has left it.
  void waitForListenerToLeave();
  /// \brief Stops the listener for good (it leaves at its next check of listenStop()).
  void stopListener();
  /// \brief The listener pauses \p pause (after an error) unless stopped meanwhile.
  void pauseListener(std::chrono::milliseconds pause);

  /// \brief Set when the listener is to leave the port (read by its listen loop).
  const std::atomic<bool>& listenStop() const { return listen_stop_; }

 private:
  // Guarded by the slot's mutex_; its changed_ is notified on a change of busy_ or listening_.
  bool listening_ = false;
  bool stop_listener_ = false;
  std::atomic<bool> listen_stop_{false};
};
}  // namespace cnc_bridge::dnc
