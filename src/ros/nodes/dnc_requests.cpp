// dnc_node's program requests (docs/dnc_node.md, "Program requests from the control"): while no
// transfer runs, a thread waits on the port for the control to punch a request program
// (`O00001 (LOAD O1234)`) and serves it: LOAD/SEND sends the program by the node's own protocol
// handler (XModem or drip-feed, ~request_mode), SAVE stores the program the control punches next,
// a refusal goes back as a short answer program. Reading the punch and the answer are the core's
// dnc::RequestListener, the decision programs::decideRequest() (as share_node's). A service call
// or ~transfer goal stops the listener and waits for it to leave the port (at most ~0.1 s), so
// requests never hold up the node's own transfers.
#include <fstream>
#include <iterator>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/program_request.h"
#include "cnc_bridge/ros/params.h"
#include "dnc_node.h"

namespace cnc_bridge
{
void DncNode::setUpRequests(ros::NodeHandle& nh, ros::NodeHandle& pnh)
{
  requests_pub_ = nh.advertise<ProgramRequestEvent>("program_requests", 20);
  // ~requests (bool, default false): listen for request programs the control punches. Off by
  // default: the node then holds the port open and writes a NAK every ~nak_interval (XModem) on a
  // line that other programs, or a status poller, may share.
  pnh.param("requests", requests_, false);
  // ~request_mode (string, default "xmodem"): how the control punches and takes programs, as its
  // RS-232 is set (Haas setting 14): xmodem (the node NAKs, the control sends blocks; a LOAD is
  // answered by ~xmodem_mode) or drip ('%'-framed text; a LOAD is answered by drip-feed).
  const std::string mode = pnh.param<std::string>("request_mode", "xmodem");
  request_options_.wire = dnc::parseRequestWire(mode);  // a typo fails at start-up
  request_protocol_ = request_options_.wire == dnc::RequestWire::kXmodem ? default_protocol_ : "drip";
  request_options_.mode = xmodem::parseMode(default_protocol_);
  request_options_.xmodem = xmodem_config_;
  request_options_.text = text_options_;
  if (request_options_.wire == dnc::RequestWire::kText)
  {
    // Text punches and answers use the drip-feed's end of block where XModem's patterns know it.
    const std::string eob = pnh.param<std::string>("drip_eob", "lf");
    try
    {
      request_options_.text.control_eob = xmodem::parseEob(eob);
    }
    catch (const ConfigError&)
    {
      ROS_WARN("request answers are sent with ~eob, not ~drip_eob '%s'", eob.c_str());
    }
  }
  // ~backup_quiet_timeout (s, default 5): a text punch without its closing '%' ends after this
  // much silence (as a backup does).
  request_options_.text_quiet = params::seconds(pnh, "backup_quiet_timeout", 5.0);
  // ~request_load_words (string, default "LOAD SEND"), ~request_save_words (string, default
  // "SAVE"): the words that make a punched program's comment a request, as share_node's.
  request_words_ = programs::RequestWords::parse(
      pnh.param<std::string>("request_load_words", "LOAD SEND"), pnh.param<std::string>("request_save_words", "SAVE"),
      pnh.resolveName("request_load_words"), pnh.resolveName("request_save_words"));
  // ~request_answer_number (int, default 1): the O number of an answer program when the request
  // program the operator punched has none (it normally has: the answer then replaces it).
  const int answer = pnh.param("request_answer_number", 1);
  answer_number_ = answer > 0 && answer <= 99999999 ? static_cast<uint32_t>(answer) : 1;
  if (!requests_)
    return;
  if (!keep_open_)
    ROS_INFO("~requests holds the port open (as ~keep_open)");
  keep_open_ = true;
  request_thread_ = std::thread([this] { requestWorker(); });
  ROS_INFO("listening for program requests on %s (%s)", serial_.device.c_str(), mode.c_str());
}

void DncNode::stopRequests()
{
  gate_.stopListener();
  if (request_thread_.joinable())
  {
    cancelRunning();  // a request being served stops at once
    request_thread_.join();
  }
}

void DncNode::requestWorker()
{
  while (gate_.waitToListen())
  {
    bool reserved = false;
    std::optional<dnc::Punch> punch;
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
    {
      ROS_ERROR_THROTTLE(60, "program requests: %s", error.c_str());
      if (reserved)
      {
        ProgramRequestEvent event;
        event.outcome = "the punch could not be read: " + error;
        publishRequest(event);
      }
    }
    if (reserved)
      gate_.release();
    if (!error.empty())
      gate_.pauseListener(std::chrono::seconds(2));  // a port that fails is tried again, not in a busy loop
  }
}

std::optional<dnc::Punch> DncNode::listenForPunch(bool& reserved)
{
  Transport& link = openLink();
  uint64_t generation = 0;
  {
    std::lock_guard<std::mutex> lock(link_mutex_);
    generation = link_generation_;
  }
  if (!listener_ || listener_generation_ != generation)  // a new port after a link error
  {
    listener_ = std::make_unique<dnc::RequestListener>(link, request_options_);
    listener_generation_ = generation;
  }
  auto may_start = [this, &reserved]
  {
    std::string refused;
    reserved = gate_.tryReserveForPunch("a program request punched by the control", refused);
    if (!reserved)
    {
      // The control began to punch just as a transfer took the port: said, not dropped unseen.
      ProgramRequestEvent event;
      event.outcome = "refused: the control began a punch as a transfer started (" + refused +
                      "); it was not read: punch it again once the transfer has ended";
      publishRequest(event);
    }
    return reserved;
  };
  return listener_->listen(gate_.listenStop(), may_start, Milliseconds(0), &gate_.cancelFlag());
}

void DncNode::servePunch(const dnc::Punch& punch)
{
  ProgramRequestEvent event;
  const auto request = programs::recogniseRequest(punch.text, false, request_words_);
  if (!request)
  {
    // Not a request: the program is kept in the archive (not in ~program_dir, where it could
    // replace a program nobody asked to replace), so nothing punched is lost.
    const programs::ProgramHeader header = programs::readHeader(punch.text);
    const std::string name = header.number ? name_pattern_->format(*header.number) : "unrequested.nc";
    event.outcome = programs::noRequestOutcome(request_words_) + " (" + name + " punched " + punch.how + ")";
    try
    {
      if (const auto kept =
              archive_->add(name, punch.text, {"dnc_node", state_->machineName(), "punched without a request"}))
        event.outcome += "; kept as version " + std::to_string(kept->number) + " in " + archive_->root();
      else
        event.outcome += "; the archive holds it already";
    }
    catch (const Error& e)
    {
      event.outcome += "; not archived: " + std::string(e.what());
    }
    publishRequest(event);
    return;
  }
  const programs::RequestDecision decision =
      programs::decideRequest(*request, *name_pattern_, *protected_, programs_->root());
  event.request = request->word;
  event.number = request->number;
  event.program = decision.program;
  state_->update(
      [&](MachineState& s)
      {
        s.execution = MachineState::EXECUTION_ACTIVE;
        s.program = decision.program;
        s.message = "request from the control: " + request->word + " " + programs::programLabel(request->number);
      });
  bool success = false;
  switch (decision.action)
  {
    case programs::RequestDecision::Action::kSend:
    {
      TransferGoal goal;
      goal.direction = TransferGoal::DIRECTION_SEND;
      goal.file = decision.program;
      goal.protocol = request_protocol_;
      bool cancelled = false;
      const TransferResult result = runReserved(goal, nullptr, cancelled);  // state, archive, lock
      event.success = result.success;
      event.outcome = result.message;
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
  state_->update(
      [&](MachineState& s)
      {
        s.execution = success ? MachineState::EXECUTION_READY : MachineState::EXECUTION_STOPPED;
        s.message = event.outcome;
      });
  publishRequest(event);
}

std::string DncNode::saveNextPunch(const std::string& name, bool& success)
{
  success = false;
  try
  {
    const std::string path = programs_->resolveForWrite(name);
    ScopedPortLock lock(port_lock_);
    // The control punches the program next: its own start, within ~start_timeout.
    const std::optional<dnc::Punch> program = listener_->listen(
        gate_.listenStop(), [] { return true; }, std::max(Milliseconds(1000), xmodem_config_.start_timeout),
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
    if (header.number && name_pattern_->format(*header.number) != name)
      outcome += " (its first block says " + programs::programLabel(*header.number) + ")";
    const auto kept = archive_->add(name, program->text, {"dnc_node", state_->machineName(), "received"});
    outcome += kept ? "; archive version " + std::to_string(kept->number) : "; the archive holds it already";
    return outcome;
  }
  catch (const Error& e)
  {
    return std::string(success ? "saved, but " : "not saved: ") + e.what();
  }
}

std::string DncNode::answerRefusal(const dnc::Punch& punch, const std::string& shown)
{
  // The answer takes the request program's own number: it replaces the operator's request on the
  // control and nothing else (never the program asked for, which may be a protected macro).
  const auto own = programs::readHeader(punch.text).number;
  const uint32_t number = own && !protected_->contains(*own) ? *own : answer_number_;
  const std::string answer = programs::answerProgram(number, shown);
  const std::string shown_line = answer.substr(2, answer.find('\n', 2) - 2);
  try
  {
    ScopedPortLock lock(port_lock_);
    const std::string how = listener_->answer(answer, &gate_.cancelFlag());
    return how + ": " + shown_line;
  }
  catch (const Error& e)
  {
    return "the answer " + shown_line + " did not reach the control: " + e.what();
  }
}

void DncNode::reportRequestInTransfer(const TransferJob& job)
{
  if (!requests_)
    return;
  std::ifstream in(job.path, std::ios::binary);
  std::string head(4096, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  const auto request = programs::recogniseRequest(head, false, request_words_);
  if (!request)
    return;
  // The control punched a request while the node was receiving: it became that transfer's file.
  ProgramRequestEvent event;
  event.request = request->word;
  event.number = request->number;
  event.program = name_pattern_->format(request->number);
  event.outcome = "refused: the request arrived during the transfer receiving " + job.goal.file +
                  " and was stored as that file; punch it again when no transfer runs";
  publishRequest(event);
}

void DncNode::publishRequest(ProgramRequestEvent& event)
{
  counters_.request(event.success);
  event.header.stamp = ros::Time::now();
  event.machine = state_->machineName();
  event.source = "rs232 " + serial_.device;
  if (event.success)
    ROS_INFO_STREAM("request from the control: " << event.outcome);
  else
    ROS_WARN_STREAM("request from the control not served: " << event.outcome);
  requests_pub_.publish(event);
}
}  // namespace cnc_bridge
