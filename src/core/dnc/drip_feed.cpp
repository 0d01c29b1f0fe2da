// DripSender: the paced, flow-controlled streaming loop, and planDrip(), which checks a program
// and works out the framing and restart preamble before a single character goes out.
#include "cnc_bridge/dnc/drip_feed.h"

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <deque>
#include <sstream>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"
#include "cnc_bridge/dnc/dnc_codes.h"
#include "cnc_bridge/programs/program_name.h"

namespace cnc_bridge
{
namespace dnc
{
using Clock = std::chrono::steady_clock;

DripFlow parseDripFlow(const std::string& text)
{
  if (text == "none")
  {
    return DripFlow::kNone;
  }
  if (text == "xonxoff" || text == "software")
  {
    return DripFlow::kXonXoff;
  }
  if (text == "rtscts" || text == "hardware")
  {
    return DripFlow::kRtsCts;
  }
  throw ConfigError("drip flow control must be none, xonxoff or rtscts, not '" + text + "'");
}

const char* toString(DripFlow flow)
{
  switch (flow)
  {
    case DripFlow::kNone:
      return "none";
    case DripFlow::kXonXoff:
      return "xonxoff";
    case DripFlow::kRtsCts:
      return "rtscts";
  }
  return "?";
}

size_t leadCharacters(const DripOptions& options)
{
  return options.xoff_allowance > options.chunk ? options.xoff_allowance - options.chunk - 1 : 0;
}

void DripOptions::validate() const
{
  if (eob.empty())
  {
    throw ConfigError("drip-feed end of block is empty");
  }
  if (chunk == 0 || chunk > xoff_allowance)
  {
    // A write larger than the allowance could all follow an XOFF.
    throw ConfigError("drip-feed chunk must be 1.." + std::to_string(xoff_allowance) + " characters, not " +
                      std::to_string(chunk));
  }
  if (!(pace_cps >= 0))
  {
    throw ConfigError("drip-feed pacing rate must be >= 0 characters per second");
  }
}

// ---------------------------------------------------------------------------------------------
// Plan

namespace
{
std::vector<std::string> splitPreamble(const std::string& text)
{
  std::vector<std::string> lines;
  std::string line;
  std::istringstream in(text);
  while (std::getline(in, line))
  {
    if (!line.empty() && line.back() == '\r')
    {
      line.pop_back();
    }
    if (line.find_first_not_of(" \t") != std::string::npos)
    {
      lines.push_back(line);
    }
  }
  return lines;
}

// The sequence number at the start of a block, cheaply: the sender looks at every line.
bool leadingSequence(const std::string& line, std::string& out)
{
  size_t i = line.find_first_not_of(" \t");
  if (i == std::string::npos || (line[i] != 'N' && line[i] != 'n'))
  {
    return false;
  }
  const size_t digits = i + 1;
  size_t end = digits;
  while (end < line.size() && line[end] >= '0' && line[end] <= '9')
  {
    ++end;
  }
  if (end == digits)
  {
    return false;
  }
  out.assign("N");
  out.append(line, digits, end - digits);
  return true;
}
}  // namespace

std::vector<CharacterIssue> checkPreamble(const std::string& preamble, const CharacterRules& rules)
{
  std::vector<CharacterIssue> issues;
  const auto lines = splitPreamble(preamble);
  for (size_t i = 0; i < lines.size(); ++i)
  {
    checkLine(lines[i], i + 1, rules, issues);
  }
  return issues;
}

DripPlan planDrip(const std::string& path, const DripOptions& options, const RestartPoint& restart,
                  const std::string& preamble)
{
  options.validate();
  DripPlan plan;
  plan.path = path;
  plan.scan = scanProgram(path, options.rules, restart, options.eob.size(), options.max_line_length);
  const ProgramScan& scan = plan.scan;
  if (restart.active())
  {
    plan.preamble = preamble.empty() ? scan.computed_preamble : preamble;
  }
  std::vector<CharacterIssue> issues = scan.issues;
  uint64_t issue_count = scan.issue_count;
  const std::vector<CharacterIssue> preamble_issues = checkPreamble(plan.preamble, options.rules);
  if (issue_count > 0 || !preamble_issues.empty())
  {
    std::ostringstream out;
    out << path << ": " << (issue_count + preamble_issues.size())
        << " character(s) the control cannot take; nothing was sent:";
    size_t shown = 0;
    for (const auto& issue : issues)
    {
      if (shown++ == 10)
      {
        break;
      }
      out << "\n  " << issue.describe();
    }
    for (const auto& issue : preamble_issues)
    {
      if (shown++ >= 10)
      {
        break;
      }
      out << "\n  restart preamble " << issue.describe();
    }
    if (issue_count + preamble_issues.size() > 10)
    {
      out << "\n  ... and " << (issue_count + preamble_issues.size() - 10) << " more";
    }
    throw ConfigError(out.str());
  }
  const bool file_percent_sent = scan.starts_with_percent && scan.start_line <= scan.first_text_line;
  plan.send_leading_percent = options.add_percent && !file_percent_sent;
  plan.send_trailing_percent = options.add_percent && !scan.ends_with_percent;

  const uint64_t eob = options.eob.size();
  uint64_t total = scan.body_bytes + options.leader_length + options.trailer_length;
  total += options.dc_codes ? 2 : 0;
  total += plan.send_leading_percent ? 1 + eob : 0;
  total += plan.send_trailing_percent ? 1 + eob : 0;
  for (const auto& line : splitPreamble(plan.preamble))
  {
    total += line.size() + eob;
  }
  plan.total_bytes = total;
  return plan;
}

// ---------------------------------------------------------------------------------------------
// Sender

namespace
{
/// Runs the calling thread at SCHED_FIFO \p priority while it lives (best effort), then restores
/// the scheduling it had.
class RealtimeScope
{
 public:
  explicit RealtimeScope(int priority)
  {
    if (priority <= 0 || pthread_getschedparam(pthread_self(), &policy_, &saved_) != 0)
    {
      return;
    }
    sched_param param{};
    param.sched_priority = priority;
    const int error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &param);
    if (error != 0)
    {
      CNC_LOG_WARN("drip-feed: SCHED_FIFO priority " << priority << " not granted (" << std::strerror(error)
                                                     << "); pacing with the normal scheduler");
      return;
    }
    changed_ = true;
  }
  ~RealtimeScope()
  {
    if (changed_)
    {
      pthread_setschedparam(pthread_self(), policy_, &saved_);
    }
  }
  RealtimeScope(const RealtimeScope&) = delete;
  RealtimeScope& operator=(const RealtimeScope&) = delete;

 private:
  int policy_ = SCHED_OTHER;
  sched_param saved_{};
  bool changed_ = false;
};
}  // namespace

class DripSender::Stopped
{
};

DripSender::DripSender(Transport& link, DripOptions options) : link_(link), options_(std::move(options))
{
  options_.validate();
  chunk_.reserve(options_.chunk);
}

void DripSender::pollInput(Milliseconds timeout)
{
  uint8_t buffer[64];
  const size_t n = link_.read(buffer, sizeof(buffer), timeout);
  for (size_t i = 0; i < n; ++i)
  {
    const uint8_t code = maskParity(buffer[i]);
    if (code == kDc3 && options_.flow == DripFlow::kXonXoff)
    {
      if (!held_)
      {
        held_ = true;
        held_since_ = Clock::now();
        ++progress_.xoff_events;
        max_queued_at_xoff_ = std::max<uint64_t>(max_queued_at_xoff_, queuedNow());
      }
    }
    else if (code == kDc1)
    {
      if (options_.flow == DripFlow::kXonXoff)
      {
        held_ = false;
      }
      waiting_for_dc1_ = false;
    }
  }
}

size_t DripSender::queuedNow() const
{
  size_t queued = link_.pendingOutput();  // the kernel's count, where the link knows it
  if (options_.pace_cps > 0)
  {
    // What the line still has to carry, as the pacing models it (a pty reports no queue).
    const double line = std::chrono::duration<double>(line_free_at_ - Clock::now()).count() * options_.pace_cps;
    queued = std::max(queued, static_cast<size_t>(std::max(0.0, std::ceil(line))));
  }
  return queued;
}

void DripSender::report(bool force)
{
  if (!callback_)
  {
    return;
  }
  const auto now = Clock::now();
  if (!force && now - last_report_ < options_.progress_interval)
  {
    return;
  }
  last_report_ = now;
  progress_.held = held_ || waiting_for_dc1_;
  progress_.paused = paused_;
  callback_(progress_);
}

void DripSender::gate()
{
  pollInput(Milliseconds(0));
  bool reported_hold = false;
  while (held_ || paused_ || waiting_for_dc1_)
  {
    if (cancelRequested())
    {
      throw Stopped();
    }
    if (!reported_hold)
    {
      report(true);  // the change to held/paused is news at once
      reported_hold = true;
    }
    else
    {
      report(false);
    }
    pollInput(Milliseconds(20));
    const auto now = Clock::now();
    if (waiting_for_dc1_ && options_.start_timeout.count() > 0 && now - held_since_ > options_.start_timeout)
    {
      throw TimeoutError(link_.describe() + ": the control did not ask for the program (no DC1) within " +
                         std::to_string(options_.start_timeout.count()) + " ms");
    }
    if (held_ && options_.hold_timeout.count() > 0 && now - held_since_ > options_.hold_timeout)
    {
      if (options_.on_hold_timeout == HoldTimeoutAction::kFail)
      {
        throw TimeoutError(link_.describe() + ": the control held the feed (XOFF) for more than " +
                           std::to_string(options_.hold_timeout.count()) + " ms without an XON");
      }
      CNC_LOG_WARN(link_.describe() << ": no XON " << options_.hold_timeout.count()
                                    << " ms after XOFF; assuming it was lost and resuming");
      held_ = false;
    }
    // Resuming after a hold: no credit for the time the line sat idle.
    line_free_at_ = Clock::now();
  }
  if (reported_hold)
  {
    report(true);
  }
  if (cancelRequested())
  {
    throw Stopped();
  }
}

void DripSender::emit(const char* data, size_t size)
{
  const bool paced = options_.pace_cps > 0;
  const auto char_time =
      paced ? std::chrono::duration<double>(1.0 / options_.pace_cps) : std::chrono::duration<double>(0);
  // Wake while the line still carries this much: the next write lands before it runs dry. What
  // is queued then, plus the write, plus the character the control's DC3 itself takes on the
  // wire (while it travels we cannot see it) stays within the allowance.
  const auto lead =
      std::chrono::duration_cast<Clock::duration>(char_time * static_cast<double>(leadCharacters(options_)));
  size_t done = 0;
  while (done < size)
  {
    if (paced)
    {
      std::this_thread::sleep_until(line_free_at_ - lead);
    }
    gate();
    const size_t n = std::min(options_.chunk, size - done);
    link_.write(reinterpret_cast<const uint8_t*>(data + done), n);
    done += n;
    progress_.bytes += n;
    if (paced)
    {
      // The line carries these n characters after what it holds; if it ran dry while we slept
      // late, it starts now (a real line cannot make up idle time, and neither do we).
      line_free_at_ = std::max(line_free_at_, Clock::now()) +
                      std::chrono::duration_cast<Clock::duration>(char_time * static_cast<double>(n));
    }
    else
    {
      link_.drain();
    }
  }
}

std::deque<std::pair<uint64_t, std::string>> DripSender::readAndCheckHead(LineReader& reader) const
{
  std::deque<std::pair<uint64_t, std::string>> lines;
  if (!options_.check_head)
    return lines;
  programs::HeaderScanner scanner;
  std::string head, line;
  while (!scanner.done() && reader.next(line))
  {
    line += '\n';
    if (head.size() + line.size() > kMaxDripHeadBytes)
      throw ConfigError("the program holds more than " + std::to_string(kMaxDripHeadBytes) +
                        " bytes before its first program block: refused");
    scanner.feed(line);
    head += line;
    line.pop_back();
    lines.emplace_back(reader.lineNumber(), line);
  }
  scanner.finish();
  options_.check_head(head);
  return lines;
}

DripResult DripSender::send(const DripPlan& plan, const ProgressCallback& progress, const LineCallback& line_sent)
{
  const RealtimeScope realtime(options_.realtime_priority);
  startFeed(plan, progress);
  DripResult result;
  SentSoFar sent;
  try
  {
    // One open file for the check and the feed: the head checked is the head sent.
    LineReader reader(plan.path, options_.max_line_length);
    std::deque<std::pair<uint64_t, std::string>> head = readAndCheckHead(reader);
    sendOpening(plan);
    sendBody(plan, reader, head, line_sent, sent);
    sendClosing(plan);
    result.outcome = DripResult::Outcome::kCompleted;
    std::ostringstream out;
    out << "sent " << progress_.bytes << " bytes (lines " << plan.scan.start_line << ".." << sent.last_line << ") to "
        << link_.describe() << ", " << progress_.xoff_events << " XOFF";
    result.message = out.str();
  }
  catch (const Stopped&)
  {
    result.outcome = DripResult::Outcome::kCancelled;
  }
  catch (const CancelledError&)
  {
    // The link was interrupted (a preempt that also interrupts the port): a cancel as well.
    result.outcome = DripResult::Outcome::kCancelled;
  }
  catch (const Error& e)
  {
    result.outcome = DripResult::Outcome::kFailed;
    std::ostringstream out;
    out << e.what() << " (after " << progress_.bytes << " bytes; last complete line " << sent.last_line;
    if (!sent.last_block.empty())
    {
      out << " " << sent.last_block;
    }
    out << ")";
    result.message = out.str();
  }
  if (result.outcome == DripResult::Outcome::kCancelled)
  {
    result.message = cancelMessage(sent);
  }
  return endFeed(result, sent);
}

void DripSender::startFeed(const DripPlan& plan, const ProgressCallback& progress)
{
  callback_ = progress;
  progress_ = DripProgress{};
  progress_.total = plan.total_bytes;
  held_ = false;
  cancelled_ = false;
  max_queued_at_xoff_ = 0;
  waiting_for_dc1_ = options_.wait_for_dc1;
  held_since_ = Clock::now();
  line_free_at_ = Clock::now();
  last_report_ = Clock::time_point();
}

void DripSender::sendOpening(const DripPlan& plan)
{
  if (options_.dc_codes)
  {
    const char dc2 = static_cast<char>(kDc2);
    emit(&dc2, 1);
  }
  const std::string leader(options_.leader_length, static_cast<char>(options_.leader_char));
  emit(leader.data(), leader.size());
  if (plan.send_leading_percent)
  {
    const std::string percent = "%" + options_.eob;
    emit(percent.data(), percent.size());
  }
  for (auto line : splitPreamble(plan.preamble))
  {
    line += options_.eob;
    emit(line.data(), line.size());
  }
}

void DripSender::sendBody(const DripPlan& plan, LineReader& reader, std::deque<std::pair<uint64_t, std::string>>& head,
                          const LineCallback& line_sent, SentSoFar& sent)
{
  // The head read for its check first, then the rest of the file.
  const auto next_line = [&](uint64_t& number, std::string& text)
  {
    if (!head.empty())
    {
      number = head.front().first;
      text = std::move(head.front().second);
      head.pop_front();
      return true;
    }
    if (!reader.next(text))
      return false;
    number = reader.lineNumber();
    return true;
  };
  std::string line;
  std::string sequence;
  uint64_t n = 0;
  while (next_line(n, line))
  {
    if (n < plan.scan.start_line)
    {
      continue;
    }
    if (n > plan.scan.last_text_line)
    {
      break;  // trailing blank lines
    }
    progress_.line = n;
    if (leadingSequence(line, sequence))
    {
      progress_.block = sequence;
    }
    const size_t text_size = line.size();
    line += options_.eob;
    emit(line.data(), line.size());
    sent.last_line = n;
    if (line_sent)
    {
      line.resize(text_size);
      line_sent(n, line);
    }
    if (!sequence.empty())
    {
      sent.last_block = sequence;
    }
    report(false);
  }
}

void DripSender::sendClosing(const DripPlan& plan)
{
  if (plan.send_trailing_percent)
  {
    const std::string percent = "%" + options_.eob;
    emit(percent.data(), percent.size());
  }
  const std::string trailer(options_.trailer_length, static_cast<char>(options_.leader_char));
  emit(trailer.data(), trailer.size());
  if (options_.dc_codes)
  {
    const char dc4 = static_cast<char>(kDc4);
    emit(&dc4, 1);
  }
  // Done means on the wire, not in a queue.
  if (options_.pace_cps > 0)
  {
    std::this_thread::sleep_until(line_free_at_);
  }
  link_.drain();
}

std::string DripSender::cancelMessage(const SentSoFar& sent) const
{
  std::ostringstream out;
  out << "cancelled after " << progress_.bytes << " bytes; last complete line " << sent.last_line;
  if (!sent.last_block.empty())
  {
    out << " (" << sent.last_block << ")";
  }
  if (progress_.line > sent.last_line)
  {
    out << "; line " << progress_.line << " was sent in part: restart from it";
  }
  return out.str();
}

DripResult DripSender::endFeed(DripResult result, const SentSoFar& sent)
{
  held_ = false;
  result.bytes = progress_.bytes;
  result.stopped_at_line = sent.last_line;
  result.stopped_at_block = sent.last_block;
  result.xoff_events = progress_.xoff_events;
  result.max_queued_at_xoff = max_queued_at_xoff_;
  report(true);
  callback_ = nullptr;
  return result;
}
}  // namespace dnc
}  // namespace cnc_bridge
