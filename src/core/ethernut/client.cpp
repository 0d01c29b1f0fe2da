// The ethernut client session (client.h): one I/O loop that owns the Transport, a queue of
// commands from other threads (each waits for its answer), and the job's stop-and-wait stream.
#include "cnc_bridge/ethernut/client.h"

#include <sstream>

#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace ethernut
{
struct Client::Completion
{
  std::mutex mutex;
  std::condition_variable cv;
  bool done = false;
  std::string error;  // empty: success
  bool timeout = false;
};

namespace
{
double toMs(std::chrono::steady_clock::duration d)
{
  return std::chrono::duration<double, std::milli>(d).count();
}

}  // namespace

const char* toString(SessionState state)
{
  switch (state)
  {
    case SessionState::kDisconnected:
      return "disconnected";
    case SessionState::kInitialising:
      return "initialising";
    case SessionState::kConnected:
      return "connected";
    case SessionState::kWaitingReady:
      return "waiting-ready";
    case SessionState::kReadyToSend:
      return "ready-to-send";
    case SessionState::kSending:
      return "sending";
    case SessionState::kPaused:
      return "paused";
    case SessionState::kKilled:
      return "killed";
    case SessionState::kStandalone:
      return "standalone";
  }
  return "?";
}

const char* toString(BoardMode mode)
{
  switch (mode)
  {
    case BoardMode::kUnknown:
      return "unknown";
    case BoardMode::kFile:
      return "file";
    case BoardMode::kGuiControl:
      return "gui-control";
    case BoardMode::kStandalone:
      return "standalone";
  }
  return "?";
}

bool parseBoardMode(const std::string& text, BoardMode& mode)
{
  for (const BoardMode candidate : {BoardMode::kFile, BoardMode::kGuiControl, BoardMode::kStandalone})
  {
    if (text == toString(candidate))
    {
      mode = candidate;
      return true;
    }
  }
  return false;
}

void addCounters(ClientStats& total, const ClientStats& more)
{
  total.coordinates_sent += more.coordinates_sent;
  total.coordinates_done += more.coordinates_done;
  total.resends += more.resends;
  total.keepalive_requests += more.keepalive_requests;
  total.keepalive_misses += more.keepalive_misses;
  total.bad_frames += more.bad_frames;
  total.unexpected_messages += more.unexpected_messages;
  total.alive_responses += more.alive_responses;
}

static Opcode modeOpcode(BoardMode mode)
{
  switch (mode)
  {
    case BoardMode::kFile:
      return Opcode::kFileMode;
    case BoardMode::kGuiControl:
      return Opcode::kGuiControlMode;
    case BoardMode::kStandalone:
      return Opcode::kStandaloneMode;
    default:
      throw ConfigError("ethernut: no opcode for board mode 'unknown'");
  }
}

Client::Client(Transport& transport, const ClientOptions& options, ClientListener* listener)
    : transport_(transport), options_(options), listener_(listener)
{
  if (options_.dead_link_timeout <= options_.keepalive_period)
  {
    throw ConfigError("ethernut: the dead-link timeout must be longer than the keepalive period");
  }
  if (options_.poll_interval.count() <= 0 || options_.reply_timeout.count() <= 0)
  {
    throw ConfigError("ethernut: poll interval and reply timeout must be positive");
  }
}

Client::~Client()
{
  stop();
}

// ---------------------------------------------------------------------------------------------
// Commands from other threads.

void Client::command(Opcode opcode, float x, float y, float z)
{
  auto done = std::make_shared<Completion>();
  {
    std::unique_lock<std::mutex> lock(mutex_);
    if (!running_ || state_ == SessionState::kInitialising)
    {
      throw LinkError(std::string("ethernut: cannot send ") + toString(opcode) + ": not connected to " +
                      transport_.describe());
    }
    queue_.push_back(Request{makeMessage(opcode, x, y, z), opcode, rowOf(opcode).response, done});
  }
  std::unique_lock<std::mutex> wait(done->mutex);
  // The run() thread enforces reply_timeout from the moment it sends; the margin covers the queue.
  const auto limit = options_.reply_timeout * 2 + options_.poll_interval * 4 + Milliseconds(1000);
  if (!done->cv.wait_for(wait, limit, [&] { return done->done; }))
  {
    throw TimeoutError(std::string("ethernut: ") + toString(opcode) + " to " + transport_.describe() +
                       " was not answered");
  }
  if (!done->error.empty())
  {
    if (done->timeout)
    {
      throw TimeoutError(done->error);
    }
    throw LinkError(done->error);
  }
}

void Client::startJob(std::function<bool(Coordinate&)> source)
{
  std::unique_lock<std::mutex> lock(mutex_);
  if (!running_ || state_ == SessionState::kInitialising || state_ == SessionState::kKilled ||
      state_ == SessionState::kStandalone)
  {
    throw LinkError("ethernut: cannot start a job: not connected to " + transport_.describe());
  }
  if (job_)
  {
    throw ProtocolError("ethernut: a job is already running");
  }
  if (state_ == SessionState::kPaused)
  {
    throw ProtocolError("ethernut: the board is paused; resume before starting a job");
  }
  if (mode_ != BoardMode::kFile)
  {
    throw ProtocolError(std::string("ethernut: jobs need file transaction mode; the board is in ") + toString(mode_) +
                        " mode");
  }
  job_ = std::make_unique<Job>();
  job_->source = std::move(source);
  job_cancel_ = false;
}

void Client::cancelJob()
{
  std::unique_lock<std::mutex> lock(mutex_);
  if (job_)
  {
    job_cancel_ = true;
  }
}

void Client::pause()
{
  {
    std::unique_lock<std::mutex> lock(mutex_);
    if (state_ == SessionState::kPaused)
    {
      return;
    }
  }
  command(Opcode::kPauseRequest);
}

void Client::resume()
{
  {
    std::unique_lock<std::mutex> lock(mutex_);
    if (state_ != SessionState::kPaused)
    {
      throw ProtocolError(std::string("ethernut: resume: the board is not paused (") + toString(state_) + ")");
    }
  }
  command(Opcode::kReadyToSend);
}

void Client::reset()
{
  command(Opcode::kReset);
}

void Client::kill()
{
  if (!options_.kill_enabled)
  {
    throw DisabledError("ethernut: kill commands are disabled (enable them with enable_kill, PROG_CNCkill|1)");
  }
  command(Opcode::kKill);
}

void Client::setMode(BoardMode mode)
{
  command(modeOpcode(mode));
}
void Client::syncOled(float x, float y, float z)
{
  command(Opcode::kSyncOled, x, y, z);
}
void Client::sendCommand(float x, float y, float z)
{
  command(Opcode::kCommand, x, y, z);
}

void Client::stop()
{
  std::unique_lock<std::mutex> lock(mutex_);
  stop_ = true;
}

SessionState Client::state() const
{
  std::unique_lock<std::mutex> lock(mutex_);
  return state_;
}

BoardMode Client::mode() const
{
  std::unique_lock<std::mutex> lock(mutex_);
  return mode_;
}

bool Client::jobActive() const
{
  std::unique_lock<std::mutex> lock(mutex_);
  return job_ != nullptr;
}

ClientStats Client::stats() const
{
  std::unique_lock<std::mutex> lock(mutex_);
  return stats_;
}

// ---------------------------------------------------------------------------------------------
// The run() thread.

void Client::send(const Message& message)
{
  const Frame frame = encode(message);
  transport_.write(frame.data(), frame.size(), options_.reply_timeout);
}

void Client::setState(std::unique_lock<std::mutex>& lock, SessionState state)
{
  if (state == state_)
  {
    return;
  }
  const SessionState previous = state_;
  state_ = state;
  if (listener_)
  {
    lock.unlock();
    listener_->onState(state, previous);
    lock.lock();
  }
}

void Client::sendRequest(std::unique_lock<std::mutex>& lock, Request request)
{
  pending_ = std::move(request);
  has_pending_ = true;
  pending_deadline_ = Clock::now() + options_.reply_timeout;
  const Message message = pending_.message;
  lock.unlock();
  send(message);
  lock.lock();
}

void Client::completePending([[maybe_unused]] std::unique_lock<std::mutex>& lock, const std::string& error)
{
  has_pending_ = false;
  if (pending_.done)
  {
    auto done = pending_.done;
    pending_.done.reset();
    std::lock_guard<std::mutex> guard(done->mutex);
    done->done = true;
    done->error = error;
    done->timeout = !error.empty();
    done->cv.notify_all();
  }
}

void Client::failAll([[maybe_unused]] std::unique_lock<std::mutex>& lock, const std::string& error)
{
  auto fail = [&](const std::shared_ptr<Completion>& done)
  {
    if (done)
    {
      std::lock_guard<std::mutex> guard(done->mutex);
      done->done = true;
      done->error = error;
      done->cv.notify_all();
    }
  };
  if (has_pending_)
  {
    fail(pending_.done);
    pending_.done.reset();
    has_pending_ = false;
  }
  for (Request& r : queue_)
  {
    fail(r.done);
  }
  queue_.clear();
}

void Client::finishJob(std::unique_lock<std::mutex>& lock, JobOutcome outcome, const std::string& message)
{
  if (!job_)
  {
    return;
  }
  job_.reset();
  job_cancel_ = false;
  if (listener_)
  {
    lock.unlock();
    listener_->onJobFinished(outcome, message);
    lock.lock();
  }
}

void Client::sendCurrent(std::unique_lock<std::mutex>& lock)
{
  job_->in_flight = true;
  job_->resend_pending = false;
  ++stats_.coordinates_sent;
  coordinate_sent_at_ = Clock::now();
  const Coordinate c = job_->current;
  setState(lock, SessionState::kSending);
  lock.unlock();
  send(makeMessage(Opcode::kCoordinates, c.x, c.y, c.z));
  lock.lock();
}

// Moves the job along and sends queued commands: called after every event.
void Client::pump(std::unique_lock<std::mutex>& lock)
{
  for (;;)
  {
    if (job_ && job_cancel_)
    {
      // A set in flight stays in flight (state kSending): the board still answers it, and the
      // next job's first set must wait for that answer (stop-and-wait), or the board would take
      // it for a second set while it moves and the answers would be paired with the wrong sets.
      finishJob(lock, JobOutcome::kCancelled, "job cancelled");
      continue;
    }
    if (job_ && !has_pending_ && state_ == SessionState::kConnected)
    {
      setState(lock, SessionState::kWaitingReady);
      sendRequest(lock, Request{makeMessage(Opcode::kReadyToSend), Opcode::kReadyToSend, Opcode::kAck, nullptr});
      continue;
    }
    if (job_ && state_ == SessionState::kReadyToSend && !job_->in_flight)
    {
      if (job_->resend_pending)
      {
        sendCurrent(lock);
        continue;
      }
      Coordinate next;
      bool more = false;
      {
        auto& source = job_->source;
        lock.unlock();
        try
        {
          more = source(next);
        }
        catch (const std::exception& e)
        {
          lock.lock();
          finishJob(lock, JobOutcome::kFailed, std::string("job source failed: ") + e.what());
          continue;
        }
        lock.lock();
      }
      if (!job_)
      {
        continue;
      }
      if (!more)
      {
        finishJob(lock, JobOutcome::kCompleted, "all " + std::to_string(job_->index) + " coordinates sent");
        continue;
      }
      job_->current = next;
      job_->resends = 0;
      try
      {
        encode(makeMessage(Opcode::kCoordinates, next.x, next.y, next.z));
      }
      catch (const ProtocolError& e)
      {
        finishJob(
            lock, JobOutcome::kFailed,
            "coordinate #" + std::to_string(job_->index) + " (tag " + std::to_string(next.tag) + "): " + e.what());
        continue;
      }
      sendCurrent(lock);
      continue;
    }
    if (!has_pending_ && !queue_.empty())
    {
      Request r = std::move(queue_.front());
      queue_.pop_front();
      sendRequest(lock, std::move(r));
      continue;
    }
    return;
  }
}

bool Client::orphanAnswered(std::unique_lock<std::mutex>& lock)
{
  if (state_ == SessionState::kSending)
  {
    setState(lock, SessionState::kReadyToSend);
    return true;
  }
  if (state_ == SessionState::kPaused && before_pause_ == SessionState::kSending)
  {
    before_pause_ = SessionState::kReadyToSend;  // answered before the board held
    return true;
  }
  return false;
}

void Client::onNext(std::unique_lock<std::mutex>& lock)
{
  if (!job_ || !job_->in_flight)
  {
    if (orphanAnswered(lock))
    {
      return;
    }
    ++stats_.unexpected_messages;
    CNC_LOG_DEBUG("ethernut: NEXT without a coordinate in flight, ignored");
    return;
  }
  const double rtt = toMs(Clock::now() - coordinate_sent_at_);
  stats_.last_rtt_ms = rtt;
  stats_.mean_rtt_ms = stats_.coordinates_done == 0 ? rtt : stats_.mean_rtt_ms + (rtt - stats_.mean_rtt_ms) / 16.0;
  stats_.max_rtt_ms = std::max(stats_.max_rtt_ms, rtt);
  ++stats_.coordinates_done;
  job_->in_flight = false;
  const uint64_t index = job_->index++;
  const Coordinate done = job_->current;
  if (state_ == SessionState::kPaused)
  {
    before_pause_ = SessionState::kReadyToSend;  // the board finished this set before holding
  }
  else
  {
    setState(lock, SessionState::kReadyToSend);
  }
  if (listener_)
  {
    lock.unlock();
    listener_->onCoordinateDone(index, done);
    lock.lock();
  }
}

void Client::onAck(std::unique_lock<std::mutex>& lock, const Message& message)
{
  if (!has_pending_ || pending_.expect != Opcode::kAck)
  {
    if ((job_ && job_->in_flight) || state_ == SessionState::kSending)
    {
      onNext(lock);  // Table 1: row 1 is answered by 16 on some boards
      return;
    }
    ++stats_.unexpected_messages;
    CNC_LOG_DEBUG("ethernut: acknowledge without a request, ignored");
    return;
  }
  const Opcode answered = pending_.opcode;
  switch (answered)
  {
    case Opcode::kInitRequest:
      break;  // handled by run()
    case Opcode::kFileMode:
      mode_ = BoardMode::kFile;
      if (state_ == SessionState::kInitialising)
      {
        setState(lock, SessionState::kConnected);
      }
      break;
    case Opcode::kGuiControlMode:
      mode_ = BoardMode::kGuiControl;
      if (state_ == SessionState::kInitialising)
      {
        setState(lock, SessionState::kConnected);
      }
      break;
    case Opcode::kStandaloneMode:
      mode_ = BoardMode::kStandalone;
      finishJob(lock, JobOutcome::kCancelled, "board switched to standalone mode");
      setState(lock, SessionState::kStandalone);
      finished_ = true;
      break;
    case Opcode::kReadyToSend:
      if (state_ == SessionState::kPaused)
      {
        setState(lock, before_pause_);  // resume: back to the state before the pause
      }
      else if (state_ == SessionState::kWaitingReady || state_ == SessionState::kConnected)
      {
        setState(lock, SessionState::kReadyToSend);
      }
      break;
    case Opcode::kReset:
      finishJob(lock, JobOutcome::kCancelled, "board reset");
      setState(lock, SessionState::kConnected);
      break;
    case Opcode::kKill:
      finishJob(lock, JobOutcome::kCancelled, "board killed");
      setState(lock, SessionState::kKilled);
      finished_ = true;
      break;
    default:
      break;
  }
  completePending(lock, "");
  (void)message;
}

void Client::handle(std::unique_lock<std::mutex>& lock, const Message& message)
{
  if (message.error != 0.0f)
  {
    onBoardError(lock, message.error);
  }
  switch (classify(message))
  {
    case Opcode::kAck:
      onAck(lock, message);
      break;
    case Opcode::kNext:
      onNext(lock);
      break;
    case Opcode::kResend:
      onResend(lock);
      break;
    case Opcode::kPauseAchieved:
      onPauseAchieved(lock);
      break;
    case Opcode::kAliveResponse:
      onAliveResponse();
      break;
    case Opcode::kAliveRequest:
      lock.unlock();
      send(makeMessage(Opcode::kAliveResponse));
      lock.lock();
      break;
    case Opcode::kPosition:
      onPosition(lock, message);
      break;
    default:
      ++stats_.unexpected_messages;
      CNC_LOG_WARN("ethernut: unexpected message from " << transport_.describe() << ": " << describe(message));
      break;
  }
}

// A message carried a non-zero error field (the board's 0-9 error code).
void Client::onBoardError(std::unique_lock<std::mutex>& lock, float code)
{
  stats_.last_board_error = code;
  if (listener_)
  {
    lock.unlock();
    listener_->onBoardError(code);
    lock.lock();
  }
}

// RESEND: the set in flight goes out again (pump()), up to max_resends times.
void Client::onResend(std::unique_lock<std::mutex>& lock)
{
  if (!job_ || !job_->in_flight)
  {
    // A cancelled job's set is not sent again; the board waits for the next one.
    if (!orphanAnswered(lock))
    {
      ++stats_.unexpected_messages;
    }
    return;
  }
  ++stats_.resends;
  ++job_->resends;
  const uint64_t index = job_->index;
  const unsigned count = job_->resends;
  if (listener_)
  {
    lock.unlock();
    listener_->onResend(index, count);
    lock.lock();
  }
  if (!job_)
  {
    return;
  }
  job_->in_flight = false;
  if (count > options_.max_resends)
  {
    std::ostringstream what;
    what << "coordinate #" << index << " (tag " << job_->current.tag << ") rejected by the board " << count
         << " times (RESEND)";
    if (state_ == SessionState::kSending)
    {
      setState(lock, SessionState::kReadyToSend);
    }
    finishJob(lock, JobOutcome::kFailed, what.str());
    return;
  }
  job_->resend_pending = true;
  if (state_ == SessionState::kSending)
  {
    setState(lock, SessionState::kReadyToSend);  // pump() sends the same set again
  }
  else if (state_ == SessionState::kPaused)
  {
    before_pause_ = SessionState::kReadyToSend;
  }
}

// Pause achieved: asked for (it answers the pending request) or the board's own (row 11 unasked).
void Client::onPauseAchieved(std::unique_lock<std::mutex>& lock)
{
  if (state_ != SessionState::kPaused)
  {
    before_pause_ = state_;
    setState(lock, SessionState::kPaused);
  }
  if (has_pending_ && pending_.opcode == Opcode::kPauseRequest)
  {
    completePending(lock, "");
  }
}

// The link's round trip: alive request -> alive response.
void Client::onAliveResponse()
{
  if (alive_outstanding_)
  {
    // The answer to the latest request (after a miss, an earlier one's late answer reads short).
    const double rtt = toMs(Clock::now() - last_alive_sent_);
    stats_.last_link_rtt_ms = rtt;
    stats_.mean_link_rtt_ms =
        stats_.alive_responses == 0 ? rtt : stats_.mean_link_rtt_ms + (rtt - stats_.mean_link_rtt_ms) / 16.0;
    stats_.max_link_rtt_ms = std::max(stats_.max_link_rtt_ms, rtt);
    ++stats_.alive_responses;
  }
  alive_outstanding_ = false;
}

// A status-4 position report: to the listener, acknowledged if the board expects it (row 4).
void Client::onPosition(std::unique_lock<std::mutex>& lock, const Message& message)
{
  if (listener_)
  {
    lock.unlock();
    listener_->onPosition(message.x, message.y, message.z);
    lock.lock();
  }
  if (options_.ack_position_reports)
  {
    lock.unlock();
    send(makeMessage(Opcode::kAck));
    lock.lock();
  }
}

void Client::checkTimers(std::unique_lock<std::mutex>& lock)
{
  const auto now = Clock::now();
  if (has_pending_ && now >= pending_deadline_)
  {
    const std::string what = std::string("ethernut: ") + toString(pending_.opcode) + " not answered by " +
                             transport_.describe() + " within " + std::to_string(options_.reply_timeout.count()) +
                             " ms";
    if (state_ == SessionState::kInitialising)
    {
      throw LinkError(what);  // init or the initial mode not acknowledged: no session
    }
    if (pending_.opcode == Opcode::kReadyToSend && state_ == SessionState::kWaitingReady)
    {
      setState(lock, SessionState::kConnected);
      finishJob(lock, JobOutcome::kFailed, what);
    }
    completePending(lock, what);
  }
  const auto silent = now - last_rx_;
  if (silent >= options_.dead_link_timeout)
  {
    std::ostringstream what;
    what << "ethernut: " << transport_.describe() << " silent for " << static_cast<long>(toMs(silent))
         << " ms (no answer to " << (alive_outstanding_ ? "alive requests" : "requests") << ")";
    throw LinkError(what.str());
  }
  const auto since_alive = now - last_alive_sent_;
  const bool keepalive = silent >= options_.keepalive_period && since_alive >= options_.keepalive_period;
  const bool probe = options_.rtt_probe_period.count() > 0 && since_alive >= options_.rtt_probe_period;
  if (keepalive || probe)
  {
    if (alive_outstanding_)
    {
      ++stats_.keepalive_misses;
    }
    alive_outstanding_ = true;
    last_alive_sent_ = now;
    ++stats_.keepalive_requests;
    lock.unlock();
    send(makeMessage(Opcode::kAliveRequest));
    lock.lock();
  }
}

void Client::run()
{
  std::unique_lock<std::mutex> lock(mutex_);
  if (running_)
  {
    throw ProtocolError("ethernut: run() is already running");
  }
  beginRun();
  std::string failure;
  try
  {
    serve(lock);
  }
  catch (const std::exception& e)
  {
    failure = e.what();
  }
  // A transport read or write that threw did so with the lock released.
  if (!lock.owns_lock())
  {
    lock.lock();
  }
  endRun(lock, failure);
}

// A new connection's session: nothing pending, the mode unknown until the handshake says it.
void Client::beginRun()
{
  running_ = true;
  stop_ = false;
  finished_ = false;
  has_pending_ = false;
  alive_outstanding_ = false;
  mode_ = BoardMode::kUnknown;
  last_rx_ = Clock::now();
  last_alive_sent_ = last_rx_;
  ++stats_.connections;
}

// The protocol loop: the handshake (init, then the initial mode), then sending what is due,
// reading and handling the board's messages, and the timers, until stopped or finished.
// 	hrows LinkError (a dead or garbled link, an unanswered handshake), as the transport.
void Client::serve(std::unique_lock<std::mutex>& lock)
{
  StreamDecoder decoder;
  uint8_t buffer[512];
  unsigned bad_in_a_row = 0;
  setState(lock, SessionState::kInitialising);
  sendRequest(lock, Request{makeMessage(Opcode::kInitRequest), Opcode::kInitRequest, Opcode::kAck, nullptr});
  bool initialised = false;
  while (!stop_ && !finished_)
  {
    if (!initialised && !has_pending_)
    {
      // Init acknowledged; the handshake ends with the mode's acknowledge (onAck), so that a
      // connected session always knows the board's mode (a job needs file mode).
      initialised = true;
      sendRequest(lock, Request{makeMessage(modeOpcode(options_.initial_mode)), modeOpcode(options_.initial_mode),
                                Opcode::kAck, nullptr});
    }
    if (initialised)
    {
      pump(lock);
    }
    if (stop_ || finished_)
    {
      break;
    }
    lock.unlock();
    const size_t n = transport_.read(buffer, sizeof buffer, options_.poll_interval);
    lock.lock();
    if (n > 0)
    {
      last_rx_ = Clock::now();
      receive(lock, decoder, buffer, n, bad_in_a_row);
    }
    checkTimers(lock);
  }
}

// Decodes \p n bytes read and handles every whole message in them.
// \throws LinkError after three invalid messages in a row (the frame boundary is lost).
void Client::receive(std::unique_lock<std::mutex>& lock, StreamDecoder& decoder, const uint8_t* data, size_t n,
                     unsigned& bad_in_a_row)
{
  size_t offset = 0;
  while (offset < n)
  {
    offset += decoder.feed(data + offset, n - offset);
    for (;;)
    {
      Message message;
      try
      {
        if (!decoder.next(message))
        {
          break;
        }
      }
      catch (const ProtocolError& e)
      {
        ++stats_.bad_frames;
        CNC_LOG_WARN(e.what() << " (from " << transport_.describe() << ")");
        // No sync marker: several bad frames in a row mean we lost the frame boundary.
        if (++bad_in_a_row >= 3)
        {
          throw LinkError("ethernut: " + transport_.describe() +
                          ": three invalid messages in a row, stream out of step");
        }
        continue;
      }
      bad_in_a_row = 0;
      handle(lock, message);
    }
  }
}

// The session's end: every waiting command and the job fail (or are cancelled when stopped), the
// state says disconnected unless the board ended it on purpose (kill, standalone).
// \throws LinkError with \p failure, if any.
void Client::endRun(std::unique_lock<std::mutex>& lock, const std::string& failure)
{
  running_ = false;
  const std::string why = failure.empty() ? std::string("ethernut: session ended") : failure;
  failAll(lock, why);
  if (job_)
  {
    finishJob(lock, failure.empty() ? JobOutcome::kCancelled : JobOutcome::kFailed,
              failure.empty() ? "session stopped" : "link lost: " + failure);
  }
  const bool keep_final = state_ == SessionState::kKilled || state_ == SessionState::kStandalone;
  if (!keep_final)
  {
    setState(lock, SessionState::kDisconnected);
  }
  if (!failure.empty())
  {
    throw LinkError(failure);
  }
}
}  // namespace ethernut
}  // namespace cnc_bridge
