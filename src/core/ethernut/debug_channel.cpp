// The board's serial debug channel (debug_channel.h): bytes to bounded, printable lines, read from
// a link the link factory opens and a ReconnectingLink keeps open.
#include "cnc_bridge/ethernut/debug_channel.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace ethernut
{
namespace
{
constexpr uint8_t kTab = 0x09;
constexpr uint8_t kLf = 0x0A;
constexpr uint8_t kCr = 0x0D;
constexpr size_t kMinLength = 8;
constexpr size_t kChunk = 512;
// A read returns at least this often, so that a stop request is seen even if it raced a reopen.
constexpr Milliseconds kReadSlice(200);

// How \p byte appears in a line: itself, \\ or \xNN.
std::string textOf(uint8_t byte, bool& escaped)
{
  escaped = false;
  if (byte == '\\')
  {
    return "\\\\";
  }
  if (byte == kTab || (byte >= 0x20 && byte <= 0x7E))
  {
    return std::string(1, static_cast<char>(byte));
  }
  static const char kHex[] = "0123456789ABCDEF";
  escaped = true;
  return std::string{'\\', 'x', kHex[byte >> 4], kHex[byte & 0x0F]};
}
}  // namespace

std::string DebugLine::display() const
{
  if (cut)
  {
    return text + " [cut]";
  }
  return unterminated ? text + " [unterminated]" : text;
}

// ------------------------------------------------------------------------------ DebugLineSplitter
DebugLineSplitter::DebugLineSplitter(size_t max_length) : max_length_(std::max(kMinLength, max_length))
{
  line_.reserve(max_length_);
}

void DebugLineSplitter::feed(const uint8_t* data, size_t size, const Handler& handler)
{
  stats_.bytes += size;
  for (size_t i = 0; i < size; ++i)
  {
    const uint8_t byte = data[i];
    if (byte == kCr || byte == kLf)
    {
      const bool second_half = byte == kLf && after_cr_;
      after_cr_ = byte == kCr;
      if (!second_half)
      {
        endLine(handler);
      }
      continue;
    }
    after_cr_ = false;
    append(byte, handler);
  }
}

void DebugLineSplitter::append(uint8_t byte, const Handler& handler)
{
  if (skipping_)
  {
    ++stats_.dropped_bytes;
    return;
  }
  bool escaped = false;
  const std::string text = textOf(byte, escaped);
  if (line_.size() + text.size() > max_length_)
  {
    // Too long: delivered cut now (its end may never come), the rest dropped up to its end.
    ++stats_.cut_lines;
    ++stats_.lines;
    ++stats_.dropped_bytes;
    skipping_ = true;
    DebugLine line{line_, true, false};
    line_.clear();
    handler(line);
    return;
  }
  stats_.escaped_bytes += escaped ? 1 : 0;
  line_ += text;
}

void DebugLineSplitter::endLine(const Handler& handler)
{
  if (skipping_)
  {
    skipping_ = false;  // the cut line ends here; the next one is whole again
    return;
  }
  if (line_.empty())
  {
    ++stats_.empty_lines;
    return;
  }
  ++stats_.lines;
  DebugLine line{line_, false, false};
  line_.clear();
  handler(line);
}

void DebugLineSplitter::endOfStream(const Handler& handler)
{
  after_cr_ = false;
  skipping_ = false;
  if (line_.empty())
  {
    return;
  }
  ++stats_.lines;
  ++stats_.unterminated;
  DebugLine line{line_, false, true};
  line_.clear();
  handler(line);
}

// ----------------------------------------------------------------------------------- DebugChannel
DebugChannel::DebugChannel(DebugChannelSettings settings)
    : settings_(std::move(settings)), open_(linkFactory(settings_.link)), splitter_(settings_.max_line)
{
  status_.device = settings_.link.hardwareId();
}

DebugChannel::~DebugChannel()
{
  stop();
}

void DebugChannel::start(LineHandler on_line, StateHandler on_state)
{
  on_line_ = std::move(on_line);
  on_state_ = std::move(on_state);
  link_ = std::make_unique<ReconnectingLink>("ethernut debug " + status_.device, open_, settings_.backoff);
  link_->start([this](Transport& link) { session(link); },
               [this](LinkState state, const std::string& why)
               {
                 {
                   std::lock_guard<std::mutex> lock(mutex_);
                   status_.link = state;
                   // The last failure stays shown while reconnecting; cleared once up.
                   if (state == LinkState::kUp || !why.empty())
                   {
                     status_.why = state == LinkState::kUp ? "" : why;
                   }
                 }
                 if (on_state_)
                 {
                   on_state_(state, why);
                 }
               });
}

void DebugChannel::stop()
{
  stopping_ = true;
  if (link_)
  {
    link_->stop();
  }
}

void DebugChannel::session(Transport& link)
{
  uint8_t buffer[kChunk];
  std::vector<DebugLine> lines;
  const auto collect = [&lines](const DebugLine& line) { lines.push_back(line); };
  try
  {
    while (!stopping_)
    {
      const size_t n = link.read(buffer, sizeof buffer, kReadSlice);
      {
        std::lock_guard<std::mutex> lock(mutex_);
        splitter_.feed(buffer, n, collect);
      }
      deliver(lines);
      lines.clear();
    }
  }
  catch (const Error&)
  {
    // The port vanished or failed: what had arrived of the last line is delivered, marked, and
    // is not glued to the first line of the next connection.
    if (!stopping_)
    {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        splitter_.endOfStream(collect);
      }
      deliver(lines);
    }
    throw;
  }
}

void DebugChannel::deliver(const std::vector<DebugLine>& lines)
{
  if (lines.empty())
  {
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    status_.last_line = lines.back().display();
  }
  for (const DebugLine& line : lines)
  {
    on_line_(line);
  }
}

DebugChannelStatus DebugChannel::status() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  DebugChannelStatus status = status_;
  status.counts = splitter_.stats();
  status.reconnects = link_ ? link_->reconnects() : 0;
  return status;
}
}  // namespace ethernut
}  // namespace cnc_bridge
