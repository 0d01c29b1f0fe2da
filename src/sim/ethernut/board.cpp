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

void Board::serve(Transport& link, StopSignal& stop)
{
  using Clock = std::chrono::steady_clock;
  StreamDecoder decoder;
  uint8_t buffer[512];
  bool silent = false;
  bool paused = false;
  bool moving = false;        // a coordinate is accepted and not yet answered with NEXT
  bool first_receipt = true;  // the coordinate in the next message has not been asked again yet
  float target[3] = {0, 0, 0};
  auto last_tick = Clock::now();
  auto last_report = Clock::time_point();
  bool position_changed = true;

  auto reply = [&](Opcode op, float x = 0, float y = 0, float z = 0)
  {
    if (!silent)
    {
      const Frame f = encode(makeMessage(op, x, y, z));
      link.write(f.data(), f.size(), Milliseconds(2000));
    }
  };

  try
  {
    while (!stop.stopped())
    {
      // Motion: advance towards the target by speed * elapsed time.
      const auto now = Clock::now();
      const double dt = std::chrono::duration<double>(now - last_tick).count();
      last_tick = now;
      if (moving && !paused)
      {
        double d[3], length = 0;
        for (int i = 0; i < 3; ++i)
        {
          d[i] = static_cast<double>(target[i]) - position_[i];
          length += d[i] * d[i];
        }
        length = std::sqrt(length);
        const double step = options_.speed_mm_per_s <= 0 ? length : options_.speed_mm_per_s * dt;
        if (step >= length)
        {
          for (int i = 0; i < 3; ++i)
          {
            position_[i] = target[i];
          }
          moving = false;
          ++accepted_;
          log(target[0], target[1], target[2]);
          reply(Opcode::kNext);
        }
        else if (length > 0)
        {
          for (int i = 0; i < 3; ++i)
          {
            position_[i] = static_cast<float>(position_[i] + d[i] * step / length);
          }
        }
        position_changed = true;
      }
      if (options_.report_period.count() > 0 && position_changed && now - last_report >= options_.report_period)
      {
        last_report = now;
        position_changed = false;
        reply(Opcode::kPosition, position_[0], position_[1], position_[2]);
      }

      const Milliseconds wait = (moving && !paused) ? Milliseconds(options_.speed_mm_per_s <= 0 ? 0 : 2)
                                                    : Milliseconds(options_.report_period.count() > 0 ? 20 : 50);
      const size_t n = link.read(buffer, sizeof buffer, wait);
      size_t offset = 0;
      while (offset < n)
      {
        offset += decoder.feed(buffer + offset, n - offset);
        for (;;)
        {
          Message m;
          try
          {
            if (!decoder.next(m))
            {
              break;
            }
          }
          catch (const ProtocolError& e)
          {
            CNC_LOG_WARN("sim_ethernut: " << e.what());
            continue;
          }
          logMessage(classify(m));
          switch (classify(m))
          {
            case Opcode::kInitRequest:
            case Opcode::kFileMode:
            case Opcode::kGuiControlMode:
            case Opcode::kSyncOled:
            case Opcode::kCommand:
              reply(Opcode::kAck);
              break;
            case Opcode::kStandaloneMode:
              reply(Opcode::kAck);
              link.close();  // standalone: the board drops its TCP clients
              return;
            case Opcode::kKill:
              reply(Opcode::kAck);
              moving = false;
              link.close();  // kill: stop everything and disconnect
              return;
            case Opcode::kReset:
              moving = false;
              paused = false;
              position_[0] = position_[1] = position_[2] = 0.0f;
              position_changed = true;
              reply(Opcode::kAck);
              break;
            case Opcode::kPauseRequest:
              paused = true;  // the simulated axes stop at once, so pause is achieved at once
              reply(Opcode::kPauseAchieved);
              break;
            case Opcode::kReadyToSend:
              paused = false;  // READYTOSEND also resumes a paused board
              reply(Opcode::kAck);
              break;
            case Opcode::kAliveRequest:
              if (options_.mute_keepalive_after == 0 || accepted_ < options_.mute_keepalive_after)
              {
                reply(Opcode::kAliveResponse);
              }
              break;
            case Opcode::kAck:
              break;  // the PC acknowledging a position report
            case Opcode::kCoordinates:
            {
              if (moving)
              {
                CNC_LOG_WARN("sim_ethernut: coordinates while the previous set is still moving");
                ++resends_;
                reply(Opcode::kResend);
                break;
              }
              const uint64_t number = ++received_;
              bool resend = false;
              if (first_receipt)
              {
                resend = (options_.resend_every > 0 && number % options_.resend_every == 0) ||
                         (options_.resend_probability > 0 &&
                          std::uniform_real_distribution<double>(0, 1)(rng_) < options_.resend_probability);
              }
              if (resend)
              {
                first_receipt = false;
                ++resends_;
                reply(Opcode::kResend);
                break;
              }
              first_receipt = true;
              target[0] = m.x;
              target[1] = m.y;
              target[2] = m.z;
              moving = true;
              const uint64_t taken = accepted_ + 1;
              if (options_.drop_after > 0 && !dropped_ && taken >= options_.drop_after)
              {
                dropped_ = true;
                link.close();
                return;
              }
              if (options_.silent_after > 0 && !silenced_ && taken >= options_.silent_after)
              {
                silenced_ = true;
                silent = true;
                moving = false;
              }
              break;
            }
            default:
              CNC_LOG_WARN("sim_ethernut: unexpected " << describe(m));
              break;
          }
        }
      }
    }
  }
  catch (const Error& e)
  {
    CNC_LOG_INFO("sim_ethernut: connection ended: " << e.what());
  }
}
}  // namespace ethernut
}  // namespace cnc_bridge
