#include "cnc_bridge/programs/program_transfers.h"

#include <boost/scope_exit.hpp>

#include <utility>

#include "cnc_bridge/common/log.h"

namespace cnc_bridge::programs
{
ProgramTransfers::ProgramTransfers(ProgramStore& store, const ProgramDirectory& folder, ProtectedRange range,
                                   NamePattern pattern, ProgramArchive& archive, VersionSource source)
    : store_(store),
      range_(std::move(range)),
      pattern_(std::move(pattern)),
      source_(std::move(source)),
      files_(folder, range_, pattern_, archive)
{
}

TransferOutcome ProgramTransfers::run(Direction direction, const std::string& file, const StoreProgress& progress,
                                      const std::function<void()>& started)
{
  if (!slot_.tryReserve((direction == Direction::kSend ? "a send of " : "a receive of ") + file))
  {
    TransferOutcome refused;
    refused.refused = true;
    refused.message = "refused: another transfer is running on " + store_.describe() + " (one at a time)";
    counters_.refused();
    return refused;
  }
  // Free however the transfer ends: an unexpected error goes on to the node's request boundary.
  BOOST_SCOPE_EXIT_ALL(this)
  {
    slot_.release();
  };
  counters_.started();
  if (started)
    started();
  TransferOutcome outcome = transfer(direction, file, progress);
  counters_.finished(outcome.success   ? TransferEnd::kCompleted
                     : outcome.refused ? TransferEnd::kRefused
                                       : TransferEnd::kFailed,
                     0, 0, outcome.bytes, outcome.message);
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
  const bool send = direction == Direction::kSend;
  try
  {
    const std::string path = files_.resolve(file, send);
    if (send)
    {
      // The protected range is checked on the bytes as they are read for the store.
      outcome.bytes =
          putProgram(store_, path, name, files_.protectedRange(), files_.names(), progress, &slot_.cancelFlag());
      outcome.message = "sent " + file + " to " + store_.describe() + "/" + name;
    }
    else
    {
      outcome.bytes = getProgram(store_, name, path, progress, &slot_.cancelFlag());
      outcome.message = "received " + store_.describe() + "/" + name + " as " + path;
    }
    keep(name, path, send ? "sent" : "received");
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
    VersionSource source = source_;
    source.direction = direction;
    const std::string kept = files_.archive(path, source);
    if (!kept.empty())
      CNC_LOG_INFO(kept);
  }
  catch (const Error& e)
  {
    // The transfer itself succeeded: a full archive disk is reported, not turned into a failure.
    CNC_LOG_ERROR(name << " was " << direction << " but not archived: " << e.what());
  }
}
}  // namespace cnc_bridge::programs
