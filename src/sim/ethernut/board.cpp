// Simulated ethernut board (board.h): one loop per connection that reads 20-byte messages,
// answers them per Table 1 and advances the simulated tool between reads.
#include "sim/ethernut/board.h"

#include <chrono>
#include <cmath>
#include <iomanip>

#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace ethernut
{
Board::Board(const BoardOptions& options) : options_(options), rng_(options.seed)
{
  if (!options_.log_path.empty())
  {
    log_.open(options_.log_path, std::ios::app);
    if (!log_)
    {
      throw ConfigError("sim_ethernut: cannot open log " + options_.log_path);
    }
  }
  if (!options_.message_log_path.empty())
  {
    message_log_.open(options_.message_log_path, std::ios::app);
    if (!message_log_)
    {
      throw ConfigError("sim_ethernut: cannot open message log " + options_.message_log_path);
    }
  }
}

std::string debugLine(const DebugMessage& message)
{
  return std::to_string(message.type) + ' ' + message.sender + ' ' + message.destination + ' ' + message.opcode + ' ' +
         std::to_string(message.opcodev);
}

void Board::say(int type, const char* sender, const char* destination, const char* opcode, int value)
{
  if (options_.debug)
  {
    options_.debug(DebugMessage{type, sender, destination, opcode, value});
  }
}

// What the board prints on its debug port for a command it received (Table 1's x as the value);
// alive requests and acknowledgements are not worth a line.
void Board::sayReceived(Opcode opcode)
{
  switch (opcode)
  {
    case Opcode::kInitRequest:
      return say(2, "GUI", "TCP", "init", 78);
    case Opcode::kFileMode:
      return say(2, "GUI", "TCP", "filemode", 15);
    case Opcode::kGuiControlMode:
      return say(2, "GUI", "TCP", "guimode", 6);
    case Opcode::kStandaloneMode:
      return say(2, "GUI", "TCP", "alone", 9);
    case Opcode::kReset:
      return say(2, "GUI", "TCP", "reset", 0);
    case Opcode::kKill:
      return say(2, "GUI", "TCP", "kill", 99);
    case Opcode::kPauseRequest:
      return say(2, "GUI", "TCP", "pause", 199);
    case Opcode::kReadyToSend:
      return say(2, "GUI", "TCP", "ready", 50);
    case Opcode::kSyncOled:
      return say(2, "GUI", "oLED", "sync", 2);
    case Opcode::kCommand:
      return say(2, "GUI", "DEBUG", "command", 3);
    default:
      return;
  }
}

void Board::log(float x, float y, float z)
{
  if (log_.is_open())
  {
    log_ << std::fixed << std::setprecision(4) << x << ' ' << y << ' ' << z << '\n';
    log_.flush();
  }
}

void Board::logMessage(Opcode opcode)
{
  if (message_log_.is_open())
  {
    message_log_ << toString(opcode) << std::endl;
  }
}

/// One connection's state while the board serves it.
struct Board::Connection
{
  using Clock = std::chrono::steady_clock;

  explicit Connection(Transport& l) : link(l) {}

  /// Answers \p op (unless the board went silent).
  void reply(Opcode op, float x = 0, float y = 0, float z = 0)
  {
    if (!silent)
    {
      const Frame f = encode(makeMessage(op, x, y, z));
      link.write(f.data(), f.size(), Milliseconds(2000));
    }
  }

  Transport& link;
  StreamDecoder decoder;
  bool silent = false;
  bool paused = false;
  bool moving = false;        // a coordinate is accepted and not yet answered with NEXT
  bool first_receipt = true;  // the coordinate in the next message has not been asked again yet
  bool closed = false;        // the board dropped the connection
  float target[3] = {0, 0, 0};
  Clock::time_point last_tick = Clock::now();
  Clock::time_point last_report;
  bool position_changed = true;
};

void Board::serve(Transport& link, StopSignal& stop)
{
  Connection c(link);
  const int number = ++connections_;
  say(1, "TCP", "GUI", "accept", number);
  uint8_t buffer[512];
  try
  {
    while (!stop.stopped() && !c.closed)
    {
      advance(c);
      const Milliseconds wait = (c.moving && !c.paused) ? Milliseconds(options_.speed_mm_per_s <= 0 ? 0 : 2)
                                                        : Milliseconds(options_.report_period.count() > 0 ? 20 : 50);
      const size_t n = link.read(buffer, sizeof buffer, wait);
      receive(c, buffer, n);
    }
  }
  catch (const Error& e)
  {
    CNC_LOG_INFO("sim_ethernut: connection ended: " << e.what());
  }
  say(1, "TCP", "GUI", "close", number);
}

// Motion: advances towards the target by speed * elapsed time (NEXT on arrival), and reports the
// position (status 4) at most every report period.
void Board::advance(Connection& c)
{
  const auto now = Connection::Clock::now();
  const double dt = std::chrono::duration<double>(now - c.last_tick).count();
  c.last_tick = now;
  if (c.moving && !c.paused)
  {
    double d[3], length = 0;
    for (int i = 0; i < 3; ++i)
    {
      d[i] = static_cast<double>(c.target[i]) - position_[i];
      length += d[i] * d[i];
    }
    length = std::sqrt(length);
    const double step = options_.speed_mm_per_s <= 0 ? length : options_.speed_mm_per_s * dt;
    if (step >= length)
    {
      for (int i = 0; i < 3; ++i)
      {
        position_[i] = c.target[i];
      }
      c.moving = false;
      ++accepted_;
      log(c.target[0], c.target[1], c.target[2]);
      c.reply(Opcode::kNext);
    }
    else if (length > 0)
    {
      for (int i = 0; i < 3; ++i)
      {
        position_[i] = static_cast<float>(position_[i] + d[i] * step / length);
      }
    }
    c.position_changed = true;
  }
  if (options_.report_period.count() > 0 && c.position_changed && now - c.last_report >= options_.report_period)
  {
    c.last_report = now;
    c.position_changed = false;
    c.reply(Opcode::kPosition, position_[0], position_[1], position_[2]);
  }
}

// Decodes \p n bytes read and answers every whole message, until the board drops the connection.
void Board::receive(Connection& c, const uint8_t* data, size_t n)
{
  size_t offset = 0;
  while (offset < n && !c.closed)
  {
    offset += c.decoder.feed(data + offset, n - offset);
    Message m;
    for (;;)
    {
      try
      {
        if (!c.decoder.next(m))
        {
          break;
        }
      }
      catch (const ProtocolError& e)
      {
        CNC_LOG_WARN("sim_ethernut: " << e.what());
        continue;
      }
      if (!answer(c, m))
      {
        c.closed = true;
        return;
      }
    }
  }
}

// Answers one message per Table 1. \returns false when the board drops the connection (standalone,
// kill, drop_after).
bool Board::answer(Connection& c, const Message& m)
{
  logMessage(classify(m));
  sayReceived(classify(m));
  switch (classify(m))
  {
    case Opcode::kInitRequest:
    case Opcode::kFileMode:
    case Opcode::kGuiControlMode:
    case Opcode::kSyncOled:
    case Opcode::kCommand:
      c.reply(Opcode::kAck);
      return true;
    case Opcode::kStandaloneMode:
      c.reply(Opcode::kAck);
      c.link.close();  // standalone: the board drops its TCP clients
      return false;
    case Opcode::kKill:
      c.reply(Opcode::kAck);
      c.moving = false;
      c.link.close();  // kill: stop everything and disconnect
      return false;
    case Opcode::kReset:
      c.moving = false;
      c.paused = false;
      position_[0] = position_[1] = position_[2] = 0.0f;
      c.position_changed = true;
      c.reply(Opcode::kAck);
      return true;
    case Opcode::kPauseRequest:
      c.paused = true;  // the simulated axes stop at once, so pause is achieved at once
      c.reply(Opcode::kPauseAchieved);
      return true;
    case Opcode::kReadyToSend:
      c.paused = false;  // READYTOSEND also resumes a paused board
      c.reply(Opcode::kAck);
      return true;
    case Opcode::kAliveRequest:
      if (options_.mute_keepalive_after == 0 || accepted_ < options_.mute_keepalive_after)
      {
        c.reply(Opcode::kAliveResponse);
      }
      return true;
    case Opcode::kAck:
      return true;  // the PC acknowledging a position report
    case Opcode::kCoordinates:
      return takeCoordinates(c, m);
    default:
      CNC_LOG_WARN("sim_ethernut: unexpected " << describe(m));
      return true;
  }
}

// A set of coordinates: asked again (RESEND) as the fault options say, else the new target.
// \returns false when drop_after closes the connection.
bool Board::takeCoordinates(Connection& c, const Message& m)
{
  if (c.moving)
  {
    CNC_LOG_WARN("sim_ethernut: coordinates while the previous set is still moving");
    ++resends_;
    say(3, "TCP", "GUI", "resend", 60);
    c.reply(Opcode::kResend);
    return true;
  }
  if (resendOnFirstReceipt(c))
  {
    ++resends_;
    say(3, "TCP", "GUI", "resend", 60);
    c.reply(Opcode::kResend);
    return true;
  }
  c.target[0] = m.x;
  c.target[1] = m.y;
  c.target[2] = m.z;
  c.moving = true;
  const uint64_t taken = accepted_ + 1;
  say(3, "GUI", "MCP", "coord", static_cast<int>(taken));
  if (options_.drop_after > 0 && !dropped_ && taken >= options_.drop_after)
  {
    dropped_ = true;
    c.link.close();
    return false;
  }
  if (options_.silent_after > 0 && !silenced_ && taken >= options_.silent_after)
  {
    silenced_ = true;
    c.silent = true;
    c.moving = false;
  }
  return true;
}

// Whether this receipt of a set is answered with RESEND (resend_every, resend_probability): only
// a first receipt is; the set sent again is taken.
bool Board::resendOnFirstReceipt(Connection& c)
{
  const uint64_t number = ++received_;
  bool resend = false;
  if (c.first_receipt)
  {
    resend = (options_.resend_every > 0 && number % options_.resend_every == 0) ||
             (options_.resend_probability > 0 &&
              std::uniform_real_distribution<double>(0, 1)(rng_) < options_.resend_probability);
  }
  c.first_receipt = !resend;
  return resend;
}
}  // namespace ethernut
}  // namespace cnc_bridge
