// Process-wide log handler of the core (see log.h).
#include "cnc_bridge/common/log.h"

#include <iostream>
#include <mutex>

namespace cnc_bridge
{
namespace
{
std::mutex& handlerMutex()
{
  static std::mutex mutex;
  return mutex;
}

LogHandler& handler()
{
  static LogHandler instance;
  return instance;
}

void defaultHandler(LogLevel level, const std::string& message)
{
  if (level >= LogLevel::kWarn)
  {
    std::cerr << "[" << toString(level) << "] " << message << std::endl;
  }
}
}  // namespace

void setLogHandler(LogHandler new_handler)
{
  std::lock_guard<std::mutex> lock(handlerMutex());
  handler() = std::move(new_handler);
}

void log(LogLevel level, const std::string& message)
{
  std::lock_guard<std::mutex> lock(handlerMutex());
  if (handler())
  {
    handler()(level, message);
  }
  else
  {
    defaultHandler(level, message);
  }
}

const char* toString(LogLevel level)
{
  switch (level)
  {
    case LogLevel::kDebug:
      return "DEBUG";
    case LogLevel::kInfo:
      return "INFO";
    case LogLevel::kWarn:
      return "WARN";
    case LogLevel::kError:
      return "ERROR";
  }
  return "?";
}
}  // namespace cnc_bridge
