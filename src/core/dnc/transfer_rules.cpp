#include "cnc_bridge/dnc/transfer_rules.h"

#include <algorithm>
#include <fstream>
#include <iterator>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::dnc
{
JobCheck TransferFiles::check(const std::string& file, bool send) const
{
  JobCheck check;
  try
  {
    const std::string path = send ? programs_.resolveExisting(file) : programs_.resolveForWrite(file);
    if (send)
      programs::checkProtectedFile(protected_, names_, path, file);
    check.path = path;
  }
  catch (const ConfigError& e)
  {
    check.refusal = std::string("refused: ") + e.what();
  }
  catch (const Error& e)  // DisabledError ("refused: ..."), or the file cannot be read
  {
    check.refusal = e.what();
    check.counted = true;
  }
  return check;
}

xmodem::ContentCheck TransferFiles::sendCheck(const std::string& file) const
{
  const std::string name = file.substr(file.find_last_of('/') + 1);
  return [this, file, name](const std::string& contents)
  { protected_.checkHeader(file, names_.number(name), programs::readHeader(contents)); };
}

std::string TransferFiles::archive(const std::string& path, const programs::VersionSource& source) const
{
  const std::string name = path.substr(path.find_last_of('/') + 1);
  std::ifstream in(path, std::ios::binary);
  const std::string content((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto kept = archive_.add(name, content, source);
  return kept ? "kept " + name + " as version " + std::to_string(kept->number) + " in " + archive_.root() : "";
}

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

std::vector<std::pair<std::string, uint64_t>> TransferTotals::fields(bool with_requests) const
{
  std::vector<std::pair<std::string, uint64_t>> fields{
      {"transfers", transfers}, {"completed", completed}, {"failed (aborts)", failed},
      {"cancelled", cancelled}, {"refused", refused},     {"blocks", blocks},
      {"retries", retries},     {"timeouts", timeouts},   {"bytes", bytes}};
  if (with_requests)
  {
    fields.emplace_back("program requests", requests);
    fields.emplace_back("program requests served", requests_served);
  }
  return fields;
}

void TransferCounters::refused()
{
  std::lock_guard<std::mutex> lock(mutex_);
  ++totals_.refused;
}

void TransferCounters::started()
{
  std::lock_guard<std::mutex> lock(mutex_);
  ++totals_.transfers;
}

void TransferCounters::finished(bool success, bool cancelled, uint64_t blocks, uint64_t retries, uint64_t bytes,
                                const std::string& message)
{
  std::lock_guard<std::mutex> lock(mutex_);
  (success ? totals_.completed : cancelled ? totals_.cancelled : totals_.failed)++;
  totals_.blocks += blocks;
  totals_.retries += retries;
  totals_.bytes += bytes;
  totals_.last_result = message;
}

void TransferCounters::xmodemStats(uint64_t timeouts, uint64_t failed_retries)
{
  std::lock_guard<std::mutex> lock(mutex_);
  totals_.timeouts += timeouts;
  totals_.retries += failed_retries;
}

void TransferCounters::request(bool served)
{
  std::lock_guard<std::mutex> lock(mutex_);
  ++totals_.requests;
  totals_.requests_served += served ? 1 : 0;
}

TransferTotals TransferCounters::totals() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return totals_;
}
}  // namespace cnc_bridge::dnc
