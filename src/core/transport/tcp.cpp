// TcpConnection and TcpServer on Boost.Asio, with connect and accept bounded in time.
#include "cnc_bridge/transport/tcp.h"
#include "cnc_bridge/transport/port_doctor.h"

#include <linux/sockios.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sys/ioctl.h>
#include <sys/socket.h>

#include <algorithm>
#include <boost/asio/connect.hpp>

namespace cnc_bridge
{
namespace asio = boost::asio;
using asio::ip::tcp;

namespace
{
std::string endpointText(const tcp::endpoint& endpoint)
{
  return endpoint.address().to_string() + ":" + std::to_string(endpoint.port());
}
}  // namespace

std::unique_ptr<TcpConnection> TcpConnection::connect(const std::string& host, uint16_t port, Milliseconds timeout)
{
  std::unique_ptr<TcpConnection> connection(new TcpConnection());
  const std::string where = host + ":" + std::to_string(port);
  connection->description_ = where;
  tcp::resolver resolver(connection->io_);
  boost::system::error_code error;
  const auto endpoints = resolver.resolve(host, std::to_string(port), error);
  if (error)
  {
    throw LinkError(where + ": cannot resolve: " + error.message());
  }
  bool done = false;
  const bool completed = detail::runWithTimeout(
      connection->io_, timeout,
      [&]
      {
        asio::async_connect(connection->stream_, endpoints,
                            [&](const boost::system::error_code& ec, const tcp::endpoint&)
                            {
                              error = ec;
                              done = true;
                            });
      },
      [&] { connection->close(); }, done);
  if (!completed)
  {
    throw LinkError(where + ": no connection within " + std::to_string(timeout.count()) +
                    " ms: " + explainConnectFailure(where, 0));
  }
  if (error)
  {
    throw LinkError(where + ": cannot connect: " + error.message() + ": " +
                    explainConnectFailure(where, error.value()));
  }
  connection->setUp(where);
  return connection;
}

TcpConnection::~TcpConnection()
{
  close();
}

void TcpConnection::setUp(const std::string& description)
{
  description_ = description;
  boost::system::error_code ignored;
  stream_.set_option(tcp::no_delay(true), ignored);
}

void TcpConnection::discardInput()
{
  uint8_t scratch[512];
  boost::system::error_code error;
  while (stream_.is_open() && stream_.available(error) > 0 && !error)
  {
    stream_.read_some(asio::buffer(scratch), error);
  }
}

void TcpConnection::shutdownSend()
{
  boost::system::error_code ignored;
  stream_.shutdown(tcp::socket::shutdown_send, ignored);
}

void TcpConnection::failUnansweredWithin(std::chrono::seconds within)
{
  // Idle: the first probe after a third of the time, then two more a sixth apart; sending:
  // unacknowledged data for the whole time. Options the kernel refuses leave the defaults.
  const int fd = stream_.native_handle();
  const int seconds = static_cast<int>(within.count());
  const int on = 1;
  const int idle = std::max(1, seconds / 3);
  const int interval = std::max(1, seconds / 6);
  const int probes = 3;
  const unsigned user_timeout_ms = static_cast<unsigned>(seconds) * 1000;
  ::setsockopt(fd, SOL_SOCKET, SO_KEEPALIVE, &on, sizeof on);
  ::setsockopt(fd, IPPROTO_TCP, TCP_KEEPIDLE, &idle, sizeof idle);
  ::setsockopt(fd, IPPROTO_TCP, TCP_KEEPINTVL, &interval, sizeof interval);
  ::setsockopt(fd, IPPROTO_TCP, TCP_KEEPCNT, &probes, sizeof probes);
  ::setsockopt(fd, IPPROTO_TCP, TCP_USER_TIMEOUT, &user_timeout_ms, sizeof user_timeout_ms);
}

size_t TcpConnection::unacknowledged() const
{
  int queued = 0;
  auto& socket = const_cast<tcp::socket&>(stream_);
  if (!socket.is_open() || ::ioctl(socket.native_handle(), SIOCOUTQ, &queued) != 0 || queued < 0)
  {
    return 0;
  }
  return static_cast<size_t>(queued);
}

TcpServer::TcpServer(uint16_t port, const std::string& address) : acceptor_(io_), address_(address)
{
  boost::system::error_code error;
  const tcp::endpoint endpoint(asio::ip::make_address(address, error), port);
  if (error)
  {
    throw LinkError("listen on " + address + ":" + std::to_string(port) + ": bad address: " + error.message());
  }
  acceptor_.open(endpoint.protocol(), error);
  if (!error)
    acceptor_.set_option(tcp::acceptor::reuse_address(true), error);
  if (!error)
    acceptor_.bind(endpoint, error);
  if (!error)
    acceptor_.listen(asio::socket_base::max_listen_connections, error);
  if (error)
  {
    throw LinkError("listen on " + address + ":" + std::to_string(port) + ": " + error.message());
  }
  port_ = acceptor_.local_endpoint().port();
}

TcpServer::~TcpServer()
{
  boost::system::error_code ignored;
  acceptor_.close(ignored);
}

std::string TcpServer::describe() const
{
  return address_ + ":" + std::to_string(port_);
}

void TcpServer::interrupt()
{
  interrupted_ = true;
  asio::post(io_,
             [this]
             {
               boost::system::error_code ignored;
               acceptor_.cancel(ignored);
             });
}

std::unique_ptr<TcpConnection> TcpServer::accept(Milliseconds timeout)
{
  for (;;)
  {
    if (interrupted_.exchange(false))
    {
      throw CancelledError(describe() + ": accept cancelled");
    }
    std::unique_ptr<TcpConnection> connection(new TcpConnection());
    boost::system::error_code error;
    bool done = false;
    // The accepted socket belongs to the connection's own io_context.
    const bool completed = detail::runWithTimeout(
        io_, timeout,
        [&]
        {
          acceptor_.async_accept(connection->stream_,
                                 [&](const boost::system::error_code& ec)
                                 {
                                   error = ec;
                                   done = true;
                                 });
        },
        [&]
        {
          boost::system::error_code ignored;
          acceptor_.cancel(ignored);
        },
        done);
    if (!completed)
    {
      if (interrupted_.exchange(false))
      {
        throw CancelledError(describe() + ": accept cancelled");
      }
      return nullptr;
    }
    if (error == asio::error::operation_aborted)
    {
      continue;  // interrupt() or a stale cancel: the loop head decides
    }
    if (error)
    {
      throw LinkError(describe() + ": accept failed: " + error.message());
    }
    boost::system::error_code ignored;
    connection->setUp(endpointText(connection->stream_.remote_endpoint(ignored)) + " (peer of " + describe() + ")");
    return connection;
  }
}
}  // namespace cnc_bridge
