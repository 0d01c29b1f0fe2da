// MdcClient and WritePolicy (see mdc_client.h).
#include "cnc_bridge/mdc/mdc_client.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace mdc
{
namespace
{
using Clock = std::chrono::steady_clock;

Milliseconds remaining(Clock::time_point deadline)
{
  const auto left = std::chrono::ceil<Milliseconds>(deadline - Clock::now());  // up: a wait, not a poll
  return std::max(left, Milliseconds(0));
}
}  // namespace

MdcClient::MdcClient(Transport& transport) : transport_(transport) {}

bool MdcClient::readLine(std::string& line, Clock::time_point deadline)
{
  for (;;)
  {
    // A complete line already buffered? CR, LF or CR LF end a line; empty lines are skipped by
    // the parser.
    const size_t end = partial_.find_first_of("\r\n");
    if (end != std::string::npos)
    {
      line = partial_.substr(0, end);
      partial_.erase(0, end + 1);
      if (overflow_)
      {
        // The tail of an oversize line: drop it with its head.
        overflow_ = false;
        continue;
      }
      return true;
    }
    if (partial_.size() > kMaxLineLength)
    {
      // Drop the head of the oversize line now and its tail when its line end comes; count it once.
      if (!overflow_)
      {
        ++stats_.dropped_lines;
        CNC_LOG_WARN("MDC " << transport_.describe() << ": dropped a line longer than " << kMaxLineLength << " bytes");
      }
      partial_.clear();
      overflow_ = true;
    }
    uint8_t buffer[256];
    const size_t n = transport_.read(buffer, sizeof buffer, remaining(deadline));
    if (n == 0 && Clock::now() >= deadline)
    {
      return false;
    }
    partial_.append(reinterpret_cast<const char*>(buffer), n);
  }
}

std::optional<Reply> MdcClient::replyIn(const std::string& line)
{
  // A Classic frames each reply in STX ... ETB; the program's DPRNT lines come bare.
  if (!text_listener_ || line.find_first_of("\x02\x17") != std::string::npos)
  {
    return parseReply(line);
  }
  std::string text;
  for (char c : line)
  {
    const auto byte = static_cast<unsigned char>(c);
    if (byte >= 0x20 && byte != 0x7F)
      text.push_back(c);
  }
  // The prompt the control writes after each reply starts the next line.
  const size_t start = text.find_first_not_of('>');
  if (start == std::string::npos || text[start] == '?')
  {
    return std::nullopt;  // a bare prompt, an empty line, or the echo of a query
  }
  ++stats_.text_lines;
  text_listener_(text.substr(start));
  return std::nullopt;
}

Reply MdcClient::request(const Query& query, Milliseconds timeout)
{
  const auto started = Clock::now();
  const auto deadline = started + timeout;
  transport_.write(query.text() + "\r\n", timeout);
  ++stats_.sent;
  std::string line;
  while (readLine(line, deadline))
  {
    auto reply = replyIn(line);
    if (!reply)
    {
      continue;
    }
    if (answers(query, *reply))
    {
      reply->answered = query;
      const double latency = std::chrono::duration<double, std::milli>(Clock::now() - started).count();
      stats_.last_latency_ms = latency;
      stats_.max_latency_ms = std::max(stats_.max_latency_ms, latency);
      stats_.total_latency_ms += latency;
      ++stats_.answered;
      if (reply->kind == ReplyKind::kUnknownQuery)
      {
        ++stats_.rejected;
      }
      return *reply;
    }
    ++stats_.foreign;
    if (foreign_listener_)
    {
      foreign_listener_(*reply);
    }
  }
  ++stats_.unanswered;
  throw TimeoutError("MDC " + transport_.describe() + ": no reply to " + query.text() + " within " +
                     std::to_string(timeout.count()) + " ms");
}

Reply MdcClient::requestValue(const Query& query, Milliseconds timeout)
{
  Reply reply = request(query, timeout);
  if (reply.kind == ReplyKind::kUnknownQuery)
  {
    throw ProtocolError("MDC " + transport_.describe() + ": the control rejected " + query.text() + " (\"" +
                        reply.line + "\")");
  }
  return reply;
}

double MdcClient::readVariable(int variable, Milliseconds timeout)
{
  return macroOf(requestValue(macroQuery(variable), timeout)).value;
}

void MdcClient::writeVariable(int variable, double value, Milliseconds timeout)
{
  requestValue(writeQuery(variable, value), timeout);
}

void MdcClient::drainForeign(Milliseconds timeout)
{
  const auto deadline = Clock::now() + timeout;
  std::string line;
  while (readLine(line, deadline))
  {
    if (auto reply = replyIn(line))
    {
      ++stats_.foreign;
      if (foreign_listener_)
      {
        foreign_listener_(*reply);
      }
    }
  }
}

void MdcClient::discardInput()
{
  partial_.clear();
  overflow_ = false;
  transport_.discardInput();
}

WritePolicy::WritePolicy(std::vector<int> allowed, std::string parameter_name)
    : allowed_(std::move(allowed)), parameter_name_(std::move(parameter_name))
{
  std::sort(allowed_.begin(), allowed_.end());
  allowed_.erase(std::unique(allowed_.begin(), allowed_.end()), allowed_.end());
}

bool WritePolicy::allows(int variable) const
{
  return std::binary_search(allowed_.begin(), allowed_.end(), variable);
}

void WritePolicy::check(int variable) const
{
  if (allows(variable))
  {
    return;
  }
  if (allowed_.empty())
  {
    throw DisabledError("writing macro variables is disabled: list the variables that may be written in " +
                        parameter_name_);
  }
  throw DisabledError("macro variable #" + std::to_string(variable) + " is not in " + parameter_name_ +
                      " (the variables that may be written)");
}
}  // namespace mdc
}  // namespace cnc_bridge
