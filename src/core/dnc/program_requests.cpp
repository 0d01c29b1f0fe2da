// Program requests over RS-232: the idle listener and the answer (see program_requests.h).
#include "cnc_bridge/dnc/program_requests.h"

#include <algorithm>
#include <chrono>
#include <sstream>
#include <utility>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/backup.h"
#include "cnc_bridge/transport/pushback_transport.h"
#include "cnc_bridge/xmodem/packet.h"
#include "cnc_bridge/xmodem/session.h"

namespace cnc_bridge::dnc
{
namespace
{
using Clock = std::chrono::steady_clock;

/// What is left until \p deadline (at least 0); \p deadline of time_point::max() means forever.
Milliseconds until(Clock::time_point deadline)
{
  if (deadline == Clock::time_point::max())
    return Milliseconds::max();
  return std::max(Milliseconds(0), std::chrono::duration_cast<Milliseconds>(deadline - Clock::now()));
}

Clock::time_point deadlineAfter(Milliseconds timeout)
{
  return timeout.count() > 0 ? Clock::now() + timeout : Clock::time_point::max();
}

[[noreturn]] void noPunch(Transport& link, Milliseconds timeout)
{
  std::ostringstream message;
  message << link.describe() << ": the control punched nothing within " << static_cast<double>(timeout.count()) / 1000.0
          << " s (start the punch on the control: SEND with the program selected)";
  throw TimeoutError(message.str());
}
}  // namespace

RequestWire parseRequestWire(const std::string& text)
{
  if (text == "xmodem")
    return RequestWire::kXmodem;
  if (text == "drip")
    return RequestWire::kText;
  throw ConfigError("request mode '" + text + "' is not one of xmodem, drip");
}

RequestListener::RequestListener(Transport& link, RequestListenerOptions options)
    : link_(link), options_(std::move(options))
{
}

std::optional<Punch> RequestListener::listen(const std::atomic<bool>& stop, const StartCallback& may_start,
                                             Milliseconds start_timeout, const std::atomic<bool>* cancel)
{
  return options_.wire == RequestWire::kXmodem ? listenXmodem(stop, may_start, start_timeout, cancel)
                                               : listenText(stop, may_start, start_timeout, cancel);
}

std::optional<Punch> RequestListener::listenXmodem(const std::atomic<bool>& stop, const StartCallback& may_start,
                                                   Milliseconds start_timeout, const std::atomic<bool>* cancel)
{
  // A control set to XMODEM sends nothing until the receiver asks, so the idle line is asked
  // every nak_interval, as a receiver waiting for a punch asks. Bytes other than the start of a
  // block are a control's own NAKs (it waits to receive: the operator pressed RECV) or noise.
  const uint8_t request = options_.mode == xmodem::Mode::kChecksum ? xmodem::kNak : xmodem::kCrcStart;
  const auto deadline = deadlineAfter(start_timeout);
  auto next_request = Clock::now();
  int first = -1;
  while (first < 0)
  {
    if (stop || (cancel != nullptr && *cancel))
      return std::nullopt;
    if (Clock::now() >= next_request)
    {
      link_.writeByte(request);
      next_request = Clock::now() + options_.xmodem.nak_interval;
    }
    const Milliseconds wait = std::min({options_.poll, until(next_request), until(deadline)});
    const int c = link_.readByte(std::max(wait, Milliseconds(1)));
    if (c == xmodem::kSoh || c == xmodem::kStx)
      first = c;
    else if (c < 0 && Clock::now() >= deadline)
      noPunch(link_, start_timeout);
  }
  if (!may_start())
    return std::nullopt;
  // The receiver takes over from block 1's first byte: it must not ask again (the control has
  // started) and waits for the rest of the block as for any block.
  PushbackTransport line(link_);
  line.unread(static_cast<uint8_t>(first));
  xmodem::Config config = options_.xmodem;
  config.skip_initial_request = true;
  config.start_timeout = config.block_timeout;
  xmodem::Receiver receiver(line, options_.mode, xmodem::withEobReading(config, options_.text), cancel);
  std::vector<uint8_t> payload = receiver.receive();
  Punch punch;
  punch.wire_bytes = payload.size();
  punch.how = "by XModem, " + std::to_string(receiver.stats().blocks) + " blocks";
  punch.text = xmodem::fromWire(std::move(payload), options_.text);
  return punch;
}

size_t RequestListener::readSome(uint8_t* buffer, size_t size, Milliseconds timeout)
{
  if (!pending_.empty())
  {
    const size_t n = std::min(size, pending_.size());
    std::copy(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(n), buffer);
    pending_.erase(pending_.begin(), pending_.begin() + static_cast<std::ptrdiff_t>(n));
    return n;
  }
  return link_.read(buffer, size, timeout);
}

std::optional<Punch> RequestListener::listenText(const std::atomic<bool>& stop, const StartCallback& may_start,
                                                 Milliseconds start_timeout, const std::atomic<bool>* cancel)
{
  // A control set to RTS/CTS or XON/XOFF punches unasked: leader, '%', the program, '%'. The
  // backup parser (what the backup protocol stores punched programs with) reads it.
  BackupParser parser;
  std::string text;
  uint64_t wire_bytes = 0;
  uint8_t buffer[512];
  const auto deadline = deadlineAfter(start_timeout);
  auto take = [&](size_t n)
  {
    const size_t used = parser.feed(buffer, n, text);
    wire_bytes += used;
    pending_.insert(pending_.end(), buffer + used, buffer + n);  // the next punch's start
  };
  while (parser.state() == BackupParser::State::kWaitingForStart)
  {
    if (stop || (cancel != nullptr && *cancel))
      return std::nullopt;
    const size_t n =
        readSome(buffer, sizeof(buffer), std::max(Milliseconds(1), std::min(options_.poll, until(deadline))));
    if (n == 0 && Clock::now() >= deadline)
      noPunch(link_, start_timeout);
    take(n);
  }
  if (!may_start())
    return std::nullopt;
  while (parser.state() != BackupParser::State::kDone)
  {
    if (cancel != nullptr && *cancel)
      throw CancelledError(link_.describe() + ": reading the punch cancelled");
    const size_t n = readSome(buffer, sizeof(buffer), options_.text_quiet);
    if (n == 0)
    {
      parser.finish(text);  // a control set not to punch the closing '%'
      break;
    }
    take(n);
    if (text.size() > options_.max_text_bytes)
      throw ProtocolError(link_.describe() + ": the punch is longer than " + std::to_string(options_.max_text_bytes) +
                          " bytes without its closing '%' (check the control's settings and the cable)");
  }
  Punch punch;
  punch.wire_bytes = wire_bytes;
  punch.how = "as text, " + std::to_string(parser.lines()) + " lines";
  punch.text = std::move(text);
  return punch;
}

std::string RequestListener::answer(const std::string& program, const std::atomic<bool>* cancel)
{
  const std::vector<uint8_t> wire = xmodem::toWire(program, options_.text);
  if (options_.wire == RequestWire::kText)
  {
    // A few dozen characters: less than any control's buffer, so flow control never holds them.
    link_.write(wire);
    link_.drain();
    return "answered as text (" + std::to_string(wire.size()) + " bytes)";
  }
  xmodem::Sender sender(link_, options_.mode, xmodem::withEobReading(options_.xmodem, options_.text), cancel);
  const xmodem::Stats stats = sender.send(wire);
  return "answered by XModem (" + std::to_string(stats.blocks) + " blocks)";
}
}  // namespace cnc_bridge::dnc
