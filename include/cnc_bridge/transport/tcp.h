// TCP links: a connection (client side, or a peer accepted by a server) is a Transport; TcpServer
// listens and hands out one connection per accept(). Nagle's algorithm is off on every connection:
// the protocols here are small request/response messages where latency matters, not throughput.
#pragma once

#include <boost/asio/ip/tcp.hpp>
#include <chrono>
#include <memory>
#include <string>

#include "cnc_bridge/transport/asio_stream.h"

namespace cnc_bridge
{
/// \brief One TCP connection. Thread-safe only for interrupt().
class TcpConnection : public AsioStreamTransport<boost::asio::ip::tcp::socket>
{
 public:
  /// \brief Connects to \p host:\p port (name or address), trying each resolved address.
  /// \throws LinkError if no connection could be made within \p timeout.
  static std::unique_ptr<TcpConnection> connect(const std::string& host, uint16_t port, Milliseconds timeout);

  ~TcpConnection() override;

  void discardInput() override;
  std::string describe() const override { return description_; }
  /// \brief Half-closes our sending side (the peer reads end of stream).
  void shutdownSend();
  /// \brief Makes a peer that stops answering fail the connection within about \p within: keepalive
  /// probes while idle, a limit on unacknowledged data while sending (TCP_USER_TIMEOUT). Without
  /// them a cable pulled on the peer's side leaves reads waiting for hours.
  void failUnansweredWithin(std::chrono::seconds within);
  /// \returns bytes written that the peer has not acknowledged yet (SIOCOUTQ); 0 if unknown.
  size_t unacknowledged() const;

 private:
  friend class TcpServer;
  TcpConnection() = default;
  void setUp(const std::string& description);

  std::string description_;
};

/// \brief A listening socket that accepts peers one at a time. Not thread-safe.
class TcpServer
{
 public:
  /// \brief Listens on \p address:\p port; port 0 picks a free port (see port()).
  /// \throws LinkError if the port cannot be bound.
  explicit TcpServer(uint16_t port, const std::string& address = "0.0.0.0");
  ~TcpServer();

  /// \brief Waits for the next peer.
  /// \returns the connection, or nullptr if none arrived within \p timeout.
  /// \throws CancelledError after interrupt(), LinkError if the listening socket fails.
  std::unique_ptr<TcpConnection> accept(Milliseconds timeout);

  /// \brief Makes a pending or the next accept() throw CancelledError. Thread-safe.
  void interrupt();

  uint16_t port() const { return port_; }
  std::string describe() const;

 private:
  boost::asio::io_context io_;
  boost::asio::ip::tcp::acceptor acceptor_;
  uint16_t port_ = 0;
  std::string address_;
  std::atomic<bool> interrupted_{false};
};
}  // namespace cnc_bridge
