// The one exception hierarchy of cnc_bridge. Every error says where it happened (a serial port
// with its baud rate, a host:port, a file) so that a log line alone tells an operator what to check.
#pragma once

#include <stdexcept>
#include <string>

namespace cnc_bridge
{
/// \brief Base of every error thrown by cnc_bridge.
class Error : public std::runtime_error
{
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

/// \brief Nothing arrived within the time allowed.
class TimeoutError : public Error
{
 public:
  using Error::Error;
};

/// \brief The link could not be opened, or it broke (the peer closed, the adapter vanished).
class LinkError : public Error
{
 public:
  using Error::Error;
};

/// \brief The peer broke the protocol, or sent bytes that cannot be decoded.
class ProtocolError : public Error
{
 public:
  using Error::Error;
};

/// \brief The operation was cancelled from another thread (a ROS action cancel, Ctrl-C).
class CancelledError : public Error
{
 public:
  using Error::Error;
};

/// \brief A parameter, option or input file is invalid (out of range, outside the program directory).
class ConfigError : public Error
{
 public:
  using Error::Error;
};

/// \brief The request is refused because a safety switch is off (motion, kill, variable writes).
class DisabledError : public Error
{
 public:
  using Error::Error;
};
}  // namespace cnc_bridge
