// Read and write with timeouts and cross-thread interruption for any Boost.Asio stream (serial
// port, TCP socket, pty descriptor). Each transport owns a private io_context that runs only
// inside its own read() and write() calls, so a session stays a plain blocking loop that tests can
// follow, while the timeouts and cancellation come from Asio rather than hand-written poll loops.
#pragma once

#include <atomic>
#include <boost/asio.hpp>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace detail
{
/// \brief Runs one asynchronous operation on \p io for at most \p timeout.
/// \returns true if the operation completed; false if it was cancelled at the deadline.
/// The caller's \p start starts the operation; \p cancel cancels it.
template <class Start, class Cancel>
bool runWithTimeout(boost::asio::io_context& io, Milliseconds timeout, Start start, Cancel cancel, bool& done)
{
  done = false;
  start();
  io.restart();
  if (timeout == kWaitForever)
  {
    io.run();
  }
  else
  {
    io.run_for(timeout);
  }
  if (!done)
  {
    cancel();
    io.restart();
    io.run();  // lets the cancelled handler complete with operation_aborted
    return false;
  }
  return true;
}
}  // namespace detail

/// \brief Transport over a Boost.Asio stream. Thread-safe only for interrupt().
/// \tparam Base Transport or an interface derived from it (SerialLine).
template <class Stream, class Base = Transport>
class AsioStreamTransport : public Base
{
 public:
  using Transport::write;

  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override
  {
    ensureOpen();
    const auto deadline = deadlineFrom(timeout);
    for (;;)
    {
      throwIfInterrupted();
      boost::system::error_code error;
      size_t transferred = 0;
      bool done = false;
      const bool completed = detail::runWithTimeout(
          io_, remaining(deadline, timeout),
          [&]
          {
            stream_.async_read_some(boost::asio::buffer(buffer, size),
                                    [&](const boost::system::error_code& ec, size_t n)
                                    {
                                      error = ec;
                                      transferred = n;
                                      done = true;
                                    });
          },
          [&] { cancelStream(); }, done);
      if (!error)
      {
        return transferred;
      }
      if (error == boost::asio::error::operation_aborted)
      {
        throwIfInterrupted();
        if (!completed || expired(deadline, timeout))
        {
          return 0;  // timeout
        }
        continue;  // a stale cancel from an earlier interrupt(): keep waiting
      }
      onLinkFailure(error);
    }
  }

  void write(const uint8_t* data, size_t size, Milliseconds timeout) override
  {
    ensureOpen();
    throwIfInterrupted();
    boost::system::error_code error;
    bool done = false;
    const bool completed = detail::runWithTimeout(
        io_, timeout,
        [&]
        {
          boost::asio::async_write(stream_, boost::asio::buffer(data, size),
                                   [&](const boost::system::error_code& ec, size_t)
                                   {
                                     error = ec;
                                     done = true;
                                   });
        },
        [&] { cancelStream(); }, done);
    throwIfInterrupted();
    if (!completed)
    {
      throw TimeoutError(this->describe() + ": the link did not take " + std::to_string(size) + " bytes within " +
                         std::to_string(timeout.count()) + " ms (flow control holding?)");
    }
    if (error)
    {
      onLinkFailure(error);
    }
  }

  void interrupt() override
  {
    interrupted_ = true;
    boost::asio::post(io_, [this] { cancelStream(); });
  }

  bool isOpen() const override { return stream_.is_open(); }

  void close() override
  {
    boost::system::error_code ignored;
    stream_.close(ignored);
  }

 protected:
  AsioStreamTransport() : stream_(io_) {}

  /// Called when an operation fails for a reason other than timeout or interruption.
  [[noreturn]] virtual void onLinkFailure(const boost::system::error_code& error)
  {
    close();
    if (error == boost::asio::error::eof)
    {
      throw LinkError(this->describe() + ": the peer closed the connection");
    }
    throw LinkError(this->describe() + ": " + error.message());
  }

  void cancelStream()
  {
    boost::system::error_code ignored;
    stream_.cancel(ignored);
  }

  void ensureOpen()
  {
    if (!stream_.is_open())
    {
      throw LinkError(this->describe() + ": not open");
    }
  }

  void throwIfInterrupted()
  {
    if (interrupted_.exchange(false))
    {
      throw CancelledError(this->describe() + ": cancelled");
    }
  }

  static std::chrono::steady_clock::time_point deadlineFrom(Milliseconds timeout)
  {
    return timeout == kWaitForever ? std::chrono::steady_clock::time_point::max()
                                   : std::chrono::steady_clock::now() + timeout;
  }
  static Milliseconds remaining(std::chrono::steady_clock::time_point deadline, Milliseconds timeout)
  {
    if (timeout == kWaitForever)
    {
      return kWaitForever;
    }
    // Rounded up: 0.9 ms left is a wait of 1 ms, not a poll (a read of 1 ms would otherwise
    // return at once, and a loop of such reads spin).
    const auto left = std::chrono::ceil<Milliseconds>(deadline - std::chrono::steady_clock::now());
    return left.count() > 0 ? left : Milliseconds(0);
  }
  static bool expired(std::chrono::steady_clock::time_point deadline, Milliseconds timeout)
  {
    return timeout != kWaitForever && std::chrono::steady_clock::now() >= deadline;
  }

  boost::asio::io_context io_;
  Stream stream_;
  std::atomic<bool> interrupted_{false};
};
}  // namespace cnc_bridge
