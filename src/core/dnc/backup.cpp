// BackupParser (the byte rules of a punched program) and BackupReceiver (its I/O loop: start
// and quiet timeouts, cancel, atomic file).
#include "cnc_bridge/dnc/backup.h"

#include <chrono>
#include <sstream>

#include "cnc_bridge/common/atomic_file.h"
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/dnc_codes.h"

namespace cnc_bridge
{
namespace dnc
{
size_t BackupParser::feed(const uint8_t* data, size_t size, std::string& out)
{
  size_t i = 0;
  while (i < size && state_ != State::kDone)
  {
    const char c = static_cast<char>(maskParity(data[i++]));
    if (state_ == State::kWaitingForStart)
    {
      if (c == '%')
      {
        state_ = State::kInProgram;
        out.push_back('%');
        at_line_start_ = false;
      }
      else
      {
        ++leader_bytes_;
      }
      continue;
    }
    if (c == '\r' || c == '\n')
    {
      if (!at_line_start_)
      {
        out.push_back('\n');
        ++lines_;
        at_line_start_ = true;
      }
      continue;
    }
    if ((static_cast<unsigned char>(c) < 0x20 && c != '\t') || c == 0x7F)
    {
      continue;  // NUL feed, DEL (tape rub-out), DC codes, anything else the control framed with
    }
    if (c == '%')
    {
      if (!at_line_start_)
      {
        out.push_back('\n');
        ++lines_;
      }
      out.append("%\n");
      ++lines_;
      at_line_start_ = true;
      state_ = State::kDone;
      continue;
    }
    out.push_back(c);
    at_line_start_ = false;
  }
  return i;
}

void BackupParser::finish(std::string& out)
{
  if (state_ == State::kInProgram && !at_line_start_)
  {
    out.push_back('\n');
    ++lines_;
    at_line_start_ = true;
  }
}

BackupResult BackupReceiver::receive(const std::string& path, const ProgressCallback& progress)
{
  using Clock = std::chrono::steady_clock;
  cancelled_ = false;
  AtomicFileWriter file(path);
  BackupParser parser;
  BackupProgress state;
  std::string text;
  uint8_t buffer[4096];
  uint64_t received = 0;
  const auto begin = Clock::now();
  auto last_byte = begin;
  auto last_report = Clock::time_point();
  if (options_.send_dc1)
  {
    link_.writeByte(kDc1);
  }
  while (parser.state() != BackupParser::State::kDone)
  {
    if (cancelled_ || (options_.cancel != nullptr && *options_.cancel))
    {
      throw CancelledError(link_.describe() + ": backup cancelled after " + std::to_string(file.bytesWritten()) +
                           " bytes; nothing was stored");
    }
    // Short reads so that cancel() is seen within 50 ms.
    const size_t n = link_.read(buffer, sizeof(buffer), Milliseconds(50));
    const auto now = Clock::now();
    if (n == 0)
    {
      if (parser.state() == BackupParser::State::kWaitingForStart)
      {
        if (options_.start_timeout.count() > 0 && now - begin > options_.start_timeout)
        {
          throw TimeoutError(link_.describe() + ": no program ('%') arrived within " +
                             std::to_string(options_.start_timeout.count()) + " ms");
        }
      }
      else if (now - last_byte > options_.quiet_timeout)
      {
        break;  // the control does not send the closing '%': silence ends the program
      }
    }
    else
    {
      last_byte = now;
      received += n;
      if (received > options_.max_bytes)
      {
        throw ProtocolError(link_.describe() + ": more than " + std::to_string(options_.max_bytes) +
                            " bytes without the closing '%'; nothing was stored");
      }
      text.clear();
      parser.feed(buffer, n, text);
      file.write(text);
    }
    state.bytes = file.bytesWritten();
    state.line = parser.lines() + 1;
    state.started = parser.state() != BackupParser::State::kWaitingForStart;
    if (progress && now - last_report >= options_.progress_interval)
    {
      last_report = now;
      progress(state);
    }
  }
  text.clear();
  parser.finish(text);
  file.write(text);
  file.commit();
  BackupResult result;
  result.bytes = file.bytesWritten();
  result.lines = parser.lines();
  result.ended_by_percent = parser.state() == BackupParser::State::kDone;
  std::ostringstream out;
  out << "stored " << result.lines << " lines (" << result.bytes << " bytes) from " << link_.describe() << " in "
      << path << (result.ended_by_percent ? "" : ", ended by the quiet timeout (no closing '%')");
  result.message = out.str();
  if (progress)
  {
    state.bytes = result.bytes;
    state.line = result.lines;
    progress(state);
  }
  return result;
}
}  // namespace dnc
}  // namespace cnc_bridge
