#include "cnc_bridge/programs/request_server.h"

#include <utility>
#include <vector>

#include "cnc_bridge/common/log.h"

namespace cnc_bridge::programs
{
RequestServer::RequestServer(RequestWords words, NamePattern pattern, ProtectedRange range, std::string program_root,
                             Transfer transfer, Report report)
    : words_(std::move(words)),
      pattern_(std::move(pattern)),
      range_(std::move(range)),
      program_root_(std::move(program_root)),
      transfer_(std::move(transfer)),
      report_(std::move(report))
{
}

void RequestServer::setRequestFolder(std::string folder, OpenFolder open)
{
  folder_name_ = std::move(folder);
  open_folder_ = std::move(open);
  folder_.reset();
}

void RequestServer::serveRequestFiles()
{
  if (!open_folder_)
    return;
  std::vector<ProgramEntry> files;
  try
  {
    if (!folder_)  // opened once it exists (a local folder must exist to be opened)
      folder_ = open_folder_();
    files = folder_->list();
  }
  catch (const Error& e)
  {
    // A share without a requests folder is no error: said once a minute, not at every check.
    const auto now = std::chrono::steady_clock::now();
    if (!last_folder_warning_ || now - *last_folder_warning_ >= std::chrono::minutes(1))
    {
      last_folder_warning_ = now;
      CNC_LOG_WARN("requests folder: " << e.what());
    }
    return;
  }
  for (const ProgramEntry& file : files)
  {
    std::string text;
    try
    {
      // Only its head can hold the request: a large file is not read whole into memory.
      text = folder_->readHead(file.name, kRequestHeadBytes);
      folder_->remove(file.name);  // served once, whatever it held
    }
    catch (const Error& e)
    {
      CNC_LOG_WARN("request file " << file.name << ": " << e.what());
      continue;
    }
    serve(recogniseRequest(text, false, words_), "share " + folder_name_ + "/" + file.name);
  }
}

bool RequestServer::serveDprntLine(const std::string& line)
{
  const auto request = recogniseRequest(line, true, words_);
  if (request)
    serve(request, "dprnt");
  return request.has_value();
}

RequestOutcome RequestServer::serve(const std::optional<ProgramRequest>& request, const std::string& source)
{
  RequestOutcome event;
  event.source = source;
  if (!request)
  {
    event.outcome = noRequestOutcome(words_);
  }
  else
  {
    // The same decision as a request punched on RS-232 (dnc_node): what is sent, taken or refused.
    const RequestDecision decision = decideRequest(*request, pattern_, range_, program_root_);
    event.word = request->word;
    event.number = request->number;
    event.program = decision.program;
    if (decision.action == RequestDecision::Action::kRefuse)
    {
      event.outcome = decision.outcome;
    }
    else
    {
      const RequestTransfer result = transfer_(decision.action, decision.program);
      event.success = result.success;
      event.outcome = result.message;
    }
  }
  if (event.success)
    CNC_LOG_INFO("request from " << source << ": " << event.outcome);
  else
    CNC_LOG_WARN("request from " << source << " not served: " << event.outcome);
  if (report_)
    report_(event);
  return event;
}
}  // namespace cnc_bridge::programs
