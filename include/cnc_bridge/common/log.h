// Logging for the ROS-free core. The core never prints: it calls one process-wide handler that
// the application installs (ROS nodes route it to rosconsole, tools to stderr). The default handler
// writes warnings and errors to stderr.
#pragma once

#include <functional>
#include <sstream>
#include <string>

namespace cnc_bridge
{
enum class LogLevel
{
  kDebug,
  kInfo,
  kWarn,
  kError
};

using LogHandler = std::function<void(LogLevel, const std::string&)>;

/// \brief Installs the handler every core log line goes to. Thread-safe.
/// \param handler the new handler; an empty function restores the default (stderr, warnings and up).
void setLogHandler(LogHandler handler);

/// \brief Sends one line to the installed handler. Thread-safe.
void log(LogLevel level, const std::string& message);

const char* toString(LogLevel level);
}  // namespace cnc_bridge

// Stream-style helpers: CNC_LOG_WARN("port " << name << " lost"). `expr` is a chain of << operands, so
// it cannot be parenthesised.
// NOLINTBEGIN(bugprone-macro-parentheses)
#define CNC_LOG_STREAM(level, expr)                  \
  do                                                 \
  {                                                  \
    std::ostringstream cnc_log_stream_;              \
    cnc_log_stream_ << expr;                         \
    ::cnc_bridge::log(level, cnc_log_stream_.str()); \
  } while (false)
// NOLINTEND(bugprone-macro-parentheses)
#define CNC_LOG_DEBUG(expr) CNC_LOG_STREAM(::cnc_bridge::LogLevel::kDebug, expr)
#define CNC_LOG_INFO(expr) CNC_LOG_STREAM(::cnc_bridge::LogLevel::kInfo, expr)
#define CNC_LOG_WARN(expr) CNC_LOG_STREAM(::cnc_bridge::LogLevel::kWarn, expr)
#define CNC_LOG_ERROR(expr) CNC_LOG_STREAM(::cnc_bridge::LogLevel::kError, expr)
