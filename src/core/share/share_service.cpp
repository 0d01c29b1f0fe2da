// What share_node decides (see share_service.h).
#include "cnc_bridge/share/share_service.h"

#include <chrono>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::share
{
TransferRequest transferRequest(const std::string& direction, const std::string& protocol)
{
  TransferRequest request;
  const bool send = direction == "send";
  if (!send && direction != "receive")
    request.refusal = "refused: direction must be 'send' or 'receive', not '" + direction + "'";
  else if (!protocol.empty() && protocol != "smb")
    request.refusal = "refused: share_node moves whole files over SMB (protocol '' or 'smb'), not '" + protocol + "'";
  else
    request.direction =
        send ? programs::ProgramTransfers::Direction::kSend : programs::ProgramTransfers::Direction::kReceive;
  return request;
}

StoreCheck checkStore(programs::ProgramStore& store, programs::ProgramTransfers& transfers)
{
  StoreCheck check;
  if (transfers.busy())
    return check;
  check.checked = true;
  const auto start = std::chrono::steady_clock::now();
  try
  {
    store.list();
  }
  catch (const Error& e)
  {
    check.error = e.what();
  }
  check.new_error = transfers.countCheck(
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), check.error);
  return check;
}

std::optional<LinkChange> linkChange(LinkState shown, const std::string& shown_message, const std::string& error)
{
  if (error.empty() && shown != LinkState::kUp)
    return LinkChange{LinkState::kUp, "share answers"};
  if (!error.empty() && (shown != LinkState::kDown || shown_message != error))
    return LinkChange{LinkState::kDown, error};
  return std::nullopt;
}

Answer removeProgram(programs::ProgramStore& store, const std::string& file, bool enabled)
{
  Answer answer;
  if (!enabled)
  {
    answer.message = "refused: removing programs from " + store.describe() + " is off (set ~enable_remove)";
    return answer;
  }
  try
  {
    store.remove(file);
    answer.success = true;
    answer.message = "removed " + file + " from " + store.describe();
  }
  catch (const Error& e)
  {
    answer.message = e.what();
  }
  return answer;
}

int32_t listedNumber(const programs::ProgramListing& listing)
{
  const auto number = listing.header.number ? listing.header.number : listing.name_number;
  return number ? static_cast<int32_t>(*number) : -1;
}

std::string currentFile(const std::string& program_root, const std::string& file)
{
  return program_root + "/" + file.substr(file.find_last_of('/') + 1);
}

std::string fanOutSummary(const std::vector<programs::TargetResult>& results, const std::string& file)
{
  if (results.empty())
    return "no machines given: nothing published";
  std::string failed;
  size_t succeeded = 0;
  for (const programs::TargetResult& result : results)
  {
    if (result.success)
      ++succeeded;
    else
      failed += (failed.empty() ? "; failed: " : ", ") + result.target + " (" + result.message + ")";
  }
  return std::to_string(succeeded) + " of " + std::to_string(results.size()) + " machines got " + file + failed;
}

std::vector<std::string> sendProgramServices(const std::string& machine)
{
  return {machine + "/send_program", machine + "/share_node/send_program"};
}

TransfersSummary transfersSummary(const programs::TransferCounts& counts)
{
  if (counts.failed > 0 && counts.last_result == counts.last_error)
    return {true, "last transfer failed: " + counts.last_error};
  return {false, counts.last_result.empty() ? "no transfer yet" : counts.last_result};
}

std::string localTimeText(std::time_t time)
{
  char text[32];
  std::tm local{};
  ::localtime_r(&time, &local);
  std::strftime(text, sizeof text, "%Y-%m-%d %H:%M %Z", &local);
  return text;
}
}  // namespace cnc_bridge::share
