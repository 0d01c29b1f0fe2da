// A link that keeps itself open: the one way every node holds its connection to a machine.
//
// The node gives a factory that opens the link (a serial port, a TCP connection) and a session
// that talks over the open link until it fails; ReconnectingLink runs them in its own thread,
// reopens after a capped exponential backoff (a machine switched off overnight is picked up in the
// morning without hammering it), reports every change of state, and lets other threads use the
// open link (a service call that writes a command) or interrupt it (shutdown, a cancel).
#pragma once

#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "cnc_bridge/transport/backoff.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
/// \brief Keeps one Transport open in its own thread. Thread-safe.
class ReconnectingLink
{
 public:
  /// Creates and opens the link; throws (LinkError, ConfigError, ...) when it cannot. Shared, so
  /// that a protocol client built on it in the opener can keep it alive as long as the client is
  /// (a unique_ptr converts).
  using Opener = std::function<std::shared_ptr<Transport>()>;
  /// Talks over the open link until it fails (throws) or is interrupted / stopped (returns).
  using Session = std::function<void(Transport& link)>;
  /// Told of every state change, with the failure text (empty when there is none).
  using StateHandler = std::function<void(LinkState state, const std::string& why)>;

  /// \param name for log lines ("haas_mdc 10.0.0.5:5051").
  ReconnectingLink(std::string name, Opener open, Backoff backoff = Backoff());
  ~ReconnectingLink();
  ReconnectingLink(const ReconnectingLink&) = delete;
  ReconnectingLink& operator=(const ReconnectingLink&) = delete;

  /// \brief Starts the link thread. The handlers must stay valid until stop() returns.
  void start(Session session, StateHandler on_state);
  /// \brief Interrupts the link, ends the session and joins the thread; no handler runs after it
  /// returns. Idempotent.
  void stop();

  /// \brief Runs \p use on the calling thread with the open link, which stays alive while \p use
  /// runs (if it fails meanwhile, \p use's reads and writes throw as they would on any failed
  /// link). \returns false, without calling \p use, when the link is not open.
  bool withLink(const std::function<void(Transport&)>& use);
  /// \brief Interrupts a read or write in progress on the open link (the session then fails and
  /// the link is reopened), e.g. to drop a link that answers garbage.
  void interrupt();

  bool isUp() const;
  unsigned reconnects() const;
  unsigned failures() const;
  const std::string& name() const { return name_; }

 private:
  std::string name_;
  Opener open_;
  Backoff backoff_;
  mutable std::mutex mutex_;         // guards link_
  std::shared_ptr<Transport> link_;  // shared: a withLink() caller keeps it alive while it runs
  std::unique_ptr<Reconnector> reconnector_;
};
}  // namespace cnc_bridge
