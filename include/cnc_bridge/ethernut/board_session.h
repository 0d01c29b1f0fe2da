// BoardSession: ethernut_node's connection to its board, ROS-free (docs/ethernut_node.md): the
// link opened through the link factory and kept up (ReconnectingLink: backoff, reconnection), one
// Client per connection running the protocol loop (init, mode, keepalive), the board's standalone
// mode (it drops the link on purpose: no reconnecting until another mode is asked for), a reset
// that closes the connection as qCNC's does, and the counters of every connection since the start.
// The node gives a ClientListener (the client's events) and a LinkState handler (state), and
// asks client() for the running client of a service or a job.
#pragma once

#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "cnc_bridge/ethernut/client.h"
#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/transport/reconnecting_link.h"

namespace cnc_bridge
{
namespace ethernut
{
/// \brief What the session needs: the board's link and the client's options (every connection's).
struct SessionSettings
{
  LinkSettings link;     ///< a TCP link to the board (host:port)
  ClientOptions client;  ///< initial_mode: the mode of every connection (selectMode() changes it)
};

/// \brief The board's connection, kept up. Thread-safe.
class BoardSession
{
 public:
  /// \param listener the client's events, on the link thread (each connection's Client::run()).
  /// \throws ConfigError as linkFactory() for invalid link settings.
  BoardSession(SessionSettings settings, ClientListener* listener);
  ~BoardSession();
  BoardSession(const BoardSession&) = delete;
  BoardSession& operator=(const BoardSession&) = delete;

  /// \brief Starts connecting (and reconnecting); \p on_state hears every change of the link.
  void start(ReconnectingLink::StateHandler on_state);
  /// \brief Ends the connection and the reconnecting; idempotent.
  void stop();

  /// \returns the running client, or nothing with \p why ("not connected to the ethernut board at
  /// 10.0.0.5:6666") while no connection is up and initialised.
  std::shared_ptr<Client> client(std::string& why) const;
  /// \returns the latest connection's client, running or not (nothing before the first).
  std::shared_ptr<Client> latest() const;

  /// \brief ~reset's end: \p client (which sent the reset) stops, the connection closes, and the
  /// link reconnects with its backoff, the state saying why.
  void closeAfterReset(Client& client);

  /// \brief Makes \p mode the mode of every later connection; while the board is in standalone
  /// mode (no connection), lets the session reconnect in it.
  /// \returns the answer when that is all there is to do (the board is in standalone mode), else
  /// nothing (the caller switches the running client).
  std::optional<std::string> selectMode(BoardMode mode);

  /// \returns the counters of every connection since the start (round trips: the latest one's).
  ClientStats totals() const;
  unsigned reconnects() const;
  /// "10.0.0.5:6666": the board as diagnostics name it.
  std::string hardwareId() const { return settings_.link.hardwareId(); }

 private:
  struct Connection
  {
    std::shared_ptr<Transport> link;  // declared first: destroyed after the client
    std::shared_ptr<Client> client;
  };

  std::shared_ptr<Transport> connect();
  void run();
  Connection connection() const;

  SessionSettings settings_;  // client.initial_mode under mutex_
  ClientListener* listener_;
  LinkFactory open_;
  std::unique_ptr<ReconnectingLink> link_;

  mutable std::mutex mutex_;  // connection_, earlier_, standalone_, stopping_, settings_.client.initial_mode
  std::condition_variable standalone_cv_;
  Connection connection_;
  ClientStats earlier_;      // counters of the connections before connection_
  bool standalone_ = false;  // the board dropped us in standalone mode: no reconnecting
  bool stopping_ = false;
  bool reset_requested_ = false;  // the end of the running connection is a reset's, not a failure
};
}  // namespace ethernut
}  // namespace cnc_bridge
