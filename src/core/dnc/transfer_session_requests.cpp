// dnc_node's program requests (docs/dnc_node.md, "Program requests from the control"), part of the
// transfer session (include/cnc_bridge/dnc/transfer_session.h): while no transfer runs, a thread
// waits on the port for the control to punch a request program (`O00001 (LOAD O1234)`) and serves
// it: LOAD/SEND sends the program by the session's own protocol handler (XModem or drip-feed,
// ~request_mode), SAVE stores the program the control punches next, a refusal goes back as a short
// answer program. Reading the punch and the answer are RequestListener's, the decision
// programs::decideRequest() (as share_node's). A transfer asked for stops the listener and waits
// for it to leave the port (at most ~0.1 s), so requests never hold up the node's own transfers.
#include <algorithm>
#include <fstream>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"
#include "cnc_bridge/dnc/transfer_session.h"
#include "cnc_bridge/programs/program_request.h"

namespace cnc_bridge::dnc
{
void TransferSession::stop()
{
  gate_.stopListener();
  cancelRunning();  // a transfer or a request being served stops at once
  if (request_thread_.joinable())
    request_thread_.join();
}

void TransferSession::requestWorker()
{
  while (gate_.waitToListen())
  {
    bool reserved = false;
    std::optional<Punch> punch;
    std::string error;
    try
    {
      punch = listenForPunch(reserved);
    }
    catch (const CancelledError&)
    {
      // The port was interrupted for a transfer's cancel or the node's end: nothing to report
      // unless a punch was being read.
      if (reserved)
        error = "cancelled while the punch was read";
    }
    catch (const LinkError& e)
    {
      error = e.what();
      closeLink();
    }
    catch (const Error& e)
    {
      error = e.what();
    }
    gate_.leftPort();
    if (punch)
      servePunch(*punch);
    if (!error.empty())
      requestError(error, reserved);
    if (reserved)
      gate_.release();
    if (!error.empty())
      gate_.pauseListener(std::chrono::seconds(2));  // a port that fails is tried again, not in a busy loop
  }
}

void TransferSession::requestError(const std::string& error, bool reserved)
{
  // A port that keeps failing is logged once a minute, not every retry.
  const auto now = std::chrono::steady_clock::now();
  if (last_request_error_ == std::chrono::steady_clock::time_point{} ||
      now - last_request_error_ >= std::chrono::seconds(60))
  {
    last_request_error_ = now;
    CNC_LOG_ERROR("program requests: " << error);
  }
  if (!reserved)
    return;
  RequestEvent event;
  event.outcome = "the punch could not be read: " + error;
  publishRequest(event);
}

std::optional<Punch> TransferSession::listenForPunch(bool& reserved)
{
  Transport& link = openLink();
  uint64_t generation = 0;
  {
    std::lock_guard<std::mutex> lock(link_mutex_);
    generation = link_generation_;
  }
  if (!listener_port_ || listener_generation_ != generation)  // a new port after a link error
  {
    listener_port_ = std::make_unique<RequestListener>(link, requests_.listener);
    listener_generation_ = generation;
  }
  auto may_start = [this, &reserved]
  {
    std::string refused;
    reserved = gate_.tryReserveForPunch("a program request punched by the control", refused);
    if (!reserved)
    {
      // The control began to punch just as a transfer took the port: said, not dropped unseen.
      RequestEvent event;
      event.outcome = "refused: the control began a punch as a transfer started (" + refused +
                      "); it was not read: punch it again once the transfer has ended";
      publishRequest(event);
    }
    return reserved;
  };
  return listener_port_->listen(gate_.listenStop(), may_start, Milliseconds(0), &gate_.cancelFlag());
}

void TransferSession::servePunch(const Punch& punch)
{
  const auto request = programs::recogniseRequest(punch.text, false, requests_.words);
  if (!request)
  {
    keepUnrequested(punch);
    return;
  }
  const programs::RequestDecision decision =
      programs::decideRequest(*request, name_pattern_, protected_, programs_->root());
  RequestEvent event;
  event.request = request->word;
  event.number = request->number;
  event.program = decision.program;
  state({Execution::kActive, decision.program, std::nullopt,
         "request from the control: " + request->word + " " + programs::programLabel(request->number)});
  bool success = false;
  switch (decision.action)
  {
    case programs::RequestDecision::Action::kSend:
    {
      TransferRequest send;
      send.direction = kDirectionSend;
      send.file = decision.program;
      send.protocol = request_protocol_;
      const TransferOutcome outcome = runReserved(send, nullptr);  // state, archive, lock
      event.success = outcome.success;
      event.outcome = outcome.message;
      publishRequest(event);
      return;
    }
    case programs::RequestDecision::Action::kReceive:
      event.outcome = saveNextPunch(decision.program, success);
      break;
    case programs::RequestDecision::Action::kRefuse:
      event.outcome = decision.outcome + "; " + answerRefusal(punch, decision.shown);
      break;
  }
  event.success = success;
  state({success ? Execution::kReady : Execution::kStopped, std::nullopt, std::nullopt, event.outcome});
  publishRequest(event);
}

void TransferSession::keepUnrequested(const Punch& punch)
{
  // Not a request: the program is kept in the archive (not in the program directory, where it
  // could replace a program nobody asked to replace), so nothing punched is lost.
  RequestEvent event;
  const programs::ProgramHeader header = programs::readHeader(punch.text);
  const std::string name = header.number ? name_pattern_.format(*header.number) : "unrequested.nc";
  event.outcome = programs::noRequestOutcome(requests_.words) + " (" + name + " punched " + punch.how + ")";
  try
  {
    if (const auto kept = archive_.add(name, punch.text, {"dnc_node", machine_, "punched without a request"}))
      event.outcome += "; kept as version " + std::to_string(kept->number) + " in " + archive_.root();
    else
      event.outcome += "; the archive holds it already";
  }
  catch (const Error& e)
  {
    event.outcome += "; not archived: " + std::string(e.what());
  }
  publishRequest(event);
}

std::string TransferSession::saveNextPunch(const std::string& name, bool& success)
{
  success = false;
  try
  {
    const std::string path = programs_->resolveForWrite(name);
    ScopedPortLock lock(port_lock_);
    // The control punches the program next: its own start, within ~start_timeout.
    const std::optional<Punch> program = listener_port_->listen(
        gate_.listenStop(), [] { return true; }, std::max(Milliseconds(1000), settings_.xmodem.start_timeout),
        &gate_.cancelFlag());
    if (!program)
      return "not saved: the node stopped before the program came";
    AtomicFileWriter file(path);
    file.write(program->text);
    file.commit();
    success = true;
    std::string outcome = "saved " + name + " (" + std::to_string(program->text.size()) + " bytes, punched " +
                          program->how + ") in " + programs_->root();
    const programs::ProgramHeader header = programs::readHeader(program->text);
    if (header.number && name_pattern_.format(*header.number) != name)
      outcome += " (its first block says " + programs::programLabel(*header.number) + ")";
    const auto kept = archive_.add(name, program->text, {"dnc_node", machine_, "received"});
    outcome += kept ? "; archive version " + std::to_string(kept->number) : "; the archive holds it already";
    return outcome;
  }
  catch (const Error& e)
  {
    return std::string(success ? "saved, but " : "not saved: ") + e.what();
  }
}

std::string TransferSession::answerRefusal(const Punch& punch, const std::string& shown)
{
  // The answer takes the request program's own number: it replaces the operator's request on the
  // control and nothing else (never the program asked for, which may be a protected macro).
  const auto own = programs::readHeader(punch.text).number;
  const uint32_t number = own && !protected_.contains(*own) ? *own : requests_.answer_number;
  const std::string answer = programs::answerProgram(number, shown);
  const std::string shown_line = answer.substr(2, answer.find('\n', 2) - 2);
  try
  {
    ScopedPortLock lock(port_lock_);
    const std::string how = listener_port_->answer(answer, &gate_.cancelFlag());
    return how + ": " + shown_line;
  }
  catch (const Error& e)
  {
    return "the answer " + shown_line + " did not reach the control: " + e.what();
  }
}

void TransferSession::reportRequestInTransfer(const TransferJob& job)
{
  if (!requests_.enabled)
    return;
  std::ifstream in(job.path, std::ios::binary);
  std::string head(programs::kRequestHeadBytes, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  const auto request = programs::recogniseRequest(head, false, requests_.words);
  if (!request)
    return;
  // The control punched a request while the node was receiving: it became that transfer's file.
  RequestEvent event;
  event.request = request->word;
  event.number = request->number;
  event.program = name_pattern_.format(request->number);
  event.outcome = "refused: the request arrived during the transfer receiving " + job.request.file +
                  " and was stored as that file; punch it again when no transfer runs";
  publishRequest(event);
}

void TransferSession::publishRequest(const RequestEvent& event)
{
  counters_.request(event.success);
  if (event.success)
    CNC_LOG_INFO("request from the control: " << event.outcome);
  else
    CNC_LOG_WARN("request from the control not served: " << event.outcome);
  listener_.onRequest(event);
}
}  // namespace cnc_bridge::dnc
