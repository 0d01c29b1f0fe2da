#include "cnc_bridge/programs/program_transfers.h"

#include <boost/scope_exit.hpp>

#include <utility>

#include "cnc_bridge/common/log.h"

namespace cnc_bridge::programs
{
ProgramTransfers::ProgramTransfers(ProgramStore& store, const ProgramDirectory& folder, ProtectedRange range,
                                   NamePattern pattern, ProgramArchive& archive, VersionSource source)
    : store_(store),
      folder_(folder),
      range_(std::move(range)),
      pattern_(std::move(pattern)),
      archive_(archive),
      source_(std::move(source))
{
}

bool ProgramTransfers::busy() const
{
  std::lock_guard<std::mutex> lock(busy_mutex_);
  return busy_;
}

TransferOutcome ProgramTransfers::run(Direction direction, const std::string& file, const StoreProgress& progress,
                                      const std::function<void()>& started)
{
  {
    std::lock_guard<std::mutex> lock(busy_mutex_);
    if (busy_)
    {
      TransferOutcome refused;
      refused.refused = true;
      refused.message = "refused: another transfer is running on " + store_.describe() + " (one at a time)";
      std::lock_guard<std::mutex> counts(counts_mutex_);
      ++counts_.refused;
      return refused;
    }
    busy_ = true;
    cancel_ = false;
  }
  // Free however the transfer ends: an unexpected error goes on to the node's request boundary.
  BOOST_SCOPE_EXIT_ALL(this)
  {
    std::lock_guard<std::mutex> lock(busy_mutex_);
    busy_ = false;
  };
  {
    std::lock_guard<std::mutex> lock(counts_mutex_);
    ++counts_.transfers;
  }
  if (started)
    started();
  TransferOutcome outcome = transfer(direction, file, progress);
  {
    std::lock_guard<std::mutex> lock(counts_mutex_);
    (outcome.success ? counts_.completed : outcome.refused ? counts_.refused : counts_.failed)++;
    counts_.bytes += outcome.bytes;
    counts_.last_result = outcome.message;
    if (!outcome.success && !outcome.refused)
      counts_.last_error = outcome.message;
  }
  if (outcome.success)
    CNC_LOG_INFO(outcome.message);
  else
    CNC_LOG_ERROR(outcome.message);
  return outcome;
}

TransferOutcome ProgramTransfers::transfer(Direction direction, const std::string& file, const StoreProgress& progress)
{
  TransferOutcome outcome;
  const std::string name = file.substr(file.find_last_of('/') + 1);  // the name on the store
  try
  {
    if (direction == Direction::kSend)
    {
      const std::string path = folder_.resolveExisting(file);
      outcome.bytes = putProgram(store_, path, name, range_, pattern_, progress, &cancel_);
      outcome.message = "sent " + file + " to " + store_.describe() + "/" + name;
      keep(name, path, "sent");
    }
    else
    {
      const std::string path = folder_.resolveForWrite(file);
      outcome.bytes = getProgram(store_, name, path, progress, &cancel_);
      outcome.message = "received " + store_.describe() + "/" + name + " as " + path;
      keep(name, path, "received");
    }
    outcome.success = true;
    outcome.message += " (" + std::to_string(outcome.bytes) + " bytes)";
  }
  catch (const ConfigError& e)
  {
    outcome.refused = true;
    outcome.message = std::string("refused: ") + e.what();
  }
  catch (const DisabledError& e)
  {
    outcome.refused = true;
    outcome.message = e.what();
  }
  catch (const LinkError& e)
  {
    outcome.link_lost = true;
    outcome.message = e.what();
  }
  catch (const Error& e)
  {
    outcome.message = e.what();
  }
  return outcome;
}

void ProgramTransfers::keep(const std::string& name, const std::string& path, const std::string& direction)
{
  try
  {
    mode_t mode = 0;
    const std::string content = readRegularFile(path, &mode);  // a link planted since is not followed
    VersionSource source = source_;
    source.direction = direction;
    if (const auto kept = archive_.add(name, content, source, mode))
      CNC_LOG_INFO("kept " << name << " as version " << kept->number << " in " << archive_.root());
  }
  catch (const Error& e)
  {
    // The transfer itself succeeded: a full archive disk is reported, not turned into a failure.
    CNC_LOG_ERROR(name << " was " << direction << " but not archived: " << e.what());
  }
}

bool ProgramTransfers::countCheck(double round_trip, const std::string& error)
{
  std::lock_guard<std::mutex> lock(counts_mutex_);
  ++counts_.checks;
  counts_.round_trip = round_trip;
  if (error.empty())
    return false;
  ++counts_.check_failures;
  const bool changed = error != counts_.last_error;
  counts_.last_error = error;
  return changed;
}

TransferCounts ProgramTransfers::counts() const
{
  std::lock_guard<std::mutex> lock(counts_mutex_);
  return counts_;
}
}  // namespace cnc_bridge::programs
