#include "cnc_bridge/dnc/transfer_rules.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::dnc
{
std::string busyRefusal(const std::string& device, const std::string& running, const std::string& cancel_topic)
{
  // One new-goal policy for everything that moves or cuts (docs/ROS_INTERFACE.md): name what
  // runs and how to stop it; a running transfer is never replaced.
  const bool goal = running.rfind("goal ", 0) == 0;
  return "refused: another transfer is running on " + device + " (one at a time): " + running +
         (goal ? "; to replace it, cancel it first (" + cancel_topic + " with its goal id)"
               : "; a service call runs to its end: wait for it");
}

void setMaxProgramBytes(xmodem::Config& config, long long max_bytes, const std::string& parameter)
{
  if (max_bytes < 1)
    throw ConfigError(parameter + " must be at least 1 (bytes), not " + std::to_string(max_bytes));
  config.max_bytes = static_cast<uint64_t>(max_bytes);
  config.max_bytes_name = parameter;
}

xmodem::Config xmodemConfig(const XmodemWaits& waits, double characters_per_second)
{
  xmodem::Config config;
  config.start_timeout = waits.start_timeout;
  config.nak_interval = waits.nak_interval;
  config.start_wait = waits.start_wait;
  config.block_timeout = waits.block_timeout;
  config.ack_timeout = waits.ack_timeout;
  config.eot_quiet = waits.eot_quiet;
  config.wait_characters = waits.wait_characters;
  config.wait_floor = waits.wait_floor;
  xmodem::fitToLine(config, characters_per_second);  // eot_quiet: 12 characters at least
  if (waits.char_timeout.count() > 0)
    config.char_timeout = waits.char_timeout;
  if (waits.purge_quiet.count() > 0)
    config.purge_quiet = waits.purge_quiet;
  config.max_retries = waits.max_retries;
  config.eot_retries = waits.max_retries;
  // A Haas may take its time to ACK block 1 while a NAK it sent before is in flight: a second, as
  // before the waits followed the line rate, unless a shorter char_timeout was set.
  config.stale_nak_settle =
      waits.char_timeout.count() > 0 ? std::min(config.char_timeout, Milliseconds(1000)) : Milliseconds(1000);
  return config;
}

bool ProgressThrottle::due(double now_s, const xmodem::Progress& progress)
{
  const bool last = progress.total > 0 && progress.bytes >= progress.total;
  if (!last && now_s - last_s_ < period_s_)
    return false;
  last_s_ = now_s;
  return true;
}

xmodem::FileResult transferByXmodem(Transport& link, const std::string& path, bool send, const std::string& protocol,
                                    const xmodem::Config& config, const xmodem::TextOptions& text,
                                    const xmodem::ProgressCallback& progress, const std::atomic<bool>& cancel,
                                    TransferCounters& counters, const xmodem::ContentCheck& check)
{
  const xmodem::Mode mode = xmodem::parseMode(protocol);
  xmodem::Stats stats;
  try
  {
    xmodem::FileResult file = send ? xmodem::sendFile(link, path, mode, config, text, progress, &cancel, &stats, check)
                                   : xmodem::receiveFile(link, path, mode, config, text, progress, &cancel, &stats);
    counters.xmodemStats(stats.timeouts, 0);
    return file;
  }
  catch (...)
  {
    counters.xmodemStats(stats.timeouts, stats.retries);
    throw;
  }
}

}  // namespace cnc_bridge::dnc
