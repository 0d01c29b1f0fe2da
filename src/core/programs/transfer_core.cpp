#include "cnc_bridge/programs/transfer_core.h"

#include <sys/stat.h>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::programs
{
bool TransferSlot::tryReserve(const std::string& what, std::string* running)
{
  std::lock_guard<std::mutex> lock(mutex_);
  return reserveLocked(what, running);
}

bool TransferSlot::reserveLocked(const std::string& what, std::string* running)
{
  if (busy_)
  {
    if (running)
      *running = running_;
    return false;
  }
  busy_ = true;
  running_ = what;
  cancel_ = false;
  return true;
}

void TransferSlot::release()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    busy_ = false;
  }
  changed_.notify_all();
}

bool TransferSlot::busy() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return busy_;
}

std::string TransferSlot::running() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return running_;
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

void TransferCounters::finished(TransferEnd end, uint64_t blocks, uint64_t retries, uint64_t bytes,
                                const std::string& message)
{
  std::lock_guard<std::mutex> lock(mutex_);
  switch (end)
  {
    case TransferEnd::kCompleted:
      ++totals_.completed;
      break;
    case TransferEnd::kFailed:
      ++totals_.failed;
      totals_.last_error = message;
      break;
    case TransferEnd::kCancelled:
      ++totals_.cancelled;
      break;
    case TransferEnd::kRefused:
      ++totals_.refused;
      break;
  }
  totals_.blocks += blocks;
  totals_.retries += retries;
  totals_.bytes += bytes;
  totals_.last_result = message;
}

void TransferCounters::finished(bool success, bool cancelled, uint64_t blocks, uint64_t retries, uint64_t bytes,
                                const std::string& message)
{
  finished(success     ? TransferEnd::kCompleted
           : cancelled ? TransferEnd::kCancelled
                       : TransferEnd::kFailed,
           blocks, retries, bytes, message);
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

bool TransferCounters::countCheck(double round_trip, const std::string& error)
{
  std::lock_guard<std::mutex> lock(mutex_);
  ++totals_.checks;
  totals_.round_trip = round_trip;
  if (error.empty())
    return false;
  ++totals_.check_failures;
  const bool changed = error != totals_.last_error;
  totals_.last_error = error;
  return changed;
}

TransferTotals TransferCounters::totals() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return totals_;
}

std::string TransferFiles::resolve(const std::string& file, bool send) const
{
  return send ? programs_.resolveExisting(file) : programs_.resolveForWrite(file);
}

JobCheck TransferFiles::check(const std::string& file, bool send) const
{
  JobCheck check;
  try
  {
    const std::string path = resolve(file, send);
    if (send)
      checkProtectedFile(protected_, names_, path, file);
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

std::function<void(const std::string&)> TransferFiles::sendCheck(const std::string& file) const
{
  const std::string name = file.substr(file.find_last_of('/') + 1);
  return [this, file, name](const std::string& contents)
  { protected_.checkHeader(file, names_.number(name), readHeader(contents)); };
}

std::string TransferFiles::archive(const std::string& path, const VersionSource& source) const
{
  const std::string name = path.substr(path.find_last_of('/') + 1);
  mode_t mode = 0;
  const std::string content = readRegularFile(path, &mode);  // a link planted since is not followed
  const auto kept = archive_.add(name, content, source, mode);
  return kept ? "kept " + name + " as version " + std::to_string(kept->number) + " in " + archive_.root() : "";
}
}  // namespace cnc_bridge::programs
