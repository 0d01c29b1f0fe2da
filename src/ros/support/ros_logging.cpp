// Core log lines into rosconsole, so they reach /rosout and the node's log file.
#include <ros/console.h>

#include "cnc_bridge/common/log.h"
#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
void routeCoreLogToRosconsole()
{
  setLogHandler(
      [](LogLevel level, const std::string& message)
      {
        switch (level)
        {
          case LogLevel::kDebug:
            ROS_DEBUG_STREAM_NAMED("core", message);
            break;
          case LogLevel::kInfo:
            ROS_INFO_STREAM_NAMED("core", message);
            break;
          case LogLevel::kWarn:
            ROS_WARN_STREAM_NAMED("core", message);
            break;
          case LogLevel::kError:
            ROS_ERROR_STREAM_NAMED("core", message);
            break;
        }
      });
}
}  // namespace cnc_bridge
