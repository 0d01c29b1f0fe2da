// Wire traces: writing one around a link, reading one back, replaying its far side.
#include "cnc_bridge/transport/wire_trace.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <thread>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace
{
constexpr size_t kBytesPerRow = 16;
// A row: four spaces, 16 hex pairs each with a space, two spaces, the text. The hex part ends at
// this column in every row, so a reader takes the pairs from before it and ignores the text.
constexpr size_t kHexEnd = 4 + kBytesPerRow * 3;

using SystemClock = std::chrono::system_clock;

std::string utcStamp(SystemClock::time_point when, const char* format, bool micros)
{
  const std::time_t seconds = SystemClock::to_time_t(when);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  std::ostringstream out;
  out << std::put_time(&utc, format);
  if (micros)
  {
    const auto us = std::chrono::duration_cast<std::chrono::microseconds>(when.time_since_epoch()).count() % 1000000;
    out << '.' << std::setw(6) << std::setfill('0') << us;
  }
  return out.str();
}

const char* directionWords(TraceDirection direction)
{
  return direction == TraceDirection::kWritten ? "Written data" : "Read data";
}

void writeRows(std::ostream& out, const uint8_t* data, size_t size)
{
  static const char* const kHex = "0123456789abcdef";
  for (size_t row = 0; row < size; row += kBytesPerRow)
  {
    const size_t n = std::min(kBytesPerRow, size - row);
    std::string line(kHexEnd, ' ');
    std::string text;
    for (size_t i = 0; i < n; ++i)
    {
      const uint8_t byte = data[row + i];
      line[4 + 3 * i] = kHex[byte >> 4];
      line[4 + 3 * i + 1] = kHex[byte & 0x0f];
      text += (byte >= 0x20 && byte < 0x7f) ? static_cast<char>(byte) : '.';
    }
    out << line << "  " << text << '\n';
  }
}

/// "2026-11-28 08:01:02.123456" (this writer) or "30/10/2017 10:27:21" (a sniffer): seconds since
/// the epoch, UTC. \returns false for anything else.
bool parseStamp(const std::string& text, double& seconds)
{
  for (const char* format : {"%Y-%m-%d %H:%M:%S", "%d/%m/%Y %H:%M:%S"})
  {
    std::tm tm{};
    std::istringstream in(text);
    in >> std::get_time(&tm, format);
    if (in.fail())
    {
      continue;
    }
    double fraction = 0.0;  // ".123456" after the seconds, in this writer's own form
    if (in.peek() == '.' && !(in >> fraction))
    {
      return false;
    }
    in >> std::ws;
    if (!in.eof())
    {
      return false;
    }
    seconds = static_cast<double>(timegm(&tm)) + fraction;
    return true;
  }
  return false;
}

bool parseHexPair(const std::string& token, uint8_t& byte)
{
  if (token.size() != 2 || !std::isxdigit(static_cast<unsigned char>(token[0])) ||
      !std::isxdigit(static_cast<unsigned char>(token[1])))
  {
    return false;
  }
  byte = static_cast<uint8_t>(std::stoi(token, nullptr, 16));
  return true;
}

std::string hexOf(uint8_t byte)
{
  char text[8];
  std::snprintf(text, sizeof text, "%02x", byte);
  return text;
}
}  // namespace

// ---------------------------------------------------------------------------------------------
// Writing

namespace
{
/// The trace file, its folder made if missing. \throws ConfigError naming the path.
std::unique_ptr<std::ofstream> createTrace(const std::string& path)
{
  std::error_code error;
  const std::filesystem::path folder = std::filesystem::path(path).parent_path();
  if (!folder.empty())
  {
    std::filesystem::create_directories(folder, error);
  }
  auto out = std::make_unique<std::ofstream>(path, std::ios::trunc);
  if (error || !*out)
  {
    throw ConfigError("cannot create the wire trace " + path + ": check that its folder can be made and is writable" +
                      (error ? " (" + error.message() + ")" : std::string()));
  }
  return out;
}
}  // namespace

WireTraceWriter::WireTraceWriter(const std::string& path, const std::string& link, size_t max_bytes)
    : path_(path), link_(link), max_bytes_(max_bytes), out_(createTrace(path))
{
  *out_ << "# cnc_bridge wire trace of " << link << ", opened " << utcStamp(SystemClock::now(), "%F %T", true)
        << " UTC\n# \"Written data\" is what this side sent, \"Read data\" what it received; at most " << max_bytes
        << " bytes\n";
  out_->flush();
}

WireTraceWriter::~WireTraceWriter()
{
  note("closed");
}

void WireTraceWriter::record(TraceDirection direction, const uint8_t* data, size_t size)
{
  if (size == 0)
  {
    return;
  }
  const auto now = SystemClock::now();
  std::lock_guard<std::mutex> lock(mutex_);
  if (full_)
  {
    return;
  }
  if (traced_ + size > max_bytes_)
  {
    full_ = true;
    *out_ << "# the trace's limit of " << max_bytes_ << " bytes is reached: the link goes on untraced\n";
    out_->flush();
    return;
  }
  traced_ += size;
  *out_ << '[' << utcStamp(now, "%F %T", true) << "] " << directionWords(direction) << " (" << link_ << ")\n";
  writeRows(*out_, data, size);
  out_->flush();  // a trace is read after a crash or while the node runs
}

void WireTraceWriter::note(const std::string& text)
{
  std::lock_guard<std::mutex> lock(mutex_);
  *out_ << "# " << utcStamp(SystemClock::now(), "%F %T", true) << ' ' << text << '\n';
  out_->flush();
}

size_t WireTraceWriter::tracedBytes() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return traced_;
}

std::string wireTracePath(const std::string& dir, const std::string& name, SystemClock::time_point when)
{
  std::string safe;
  for (const char c : name)
  {
    safe += std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '.' ? c : '_';
  }
  safe.erase(0, safe.find_first_not_of('_'));
  return dir + "/" + safe + "-" + utcStamp(when, "%Y%m%dT%H%M%S", true) + ".trace";
}

// ---------------------------------------------------------------------------------------------
// Reading

std::vector<TraceEntry> parseWireTrace(std::istream& in, const std::string& source)
{
  std::vector<TraceEntry> entries;
  std::string line;
  size_t number = 0;
  auto fail = [&](const std::string& what)
  {
    throw ConfigError(source + " line " + std::to_string(number) + ": " + what +
                      " (a wire trace has \"[time] Written data (link)\" or \"[time] Read data (link)\" lines, each "
                      "followed by rows of hex bytes)");
  };
  while (std::getline(in, line))
  {
    ++number;
    if (!line.empty() && line.back() == '\r')
    {
      line.pop_back();
    }
    if (line.find_first_not_of(" \t") == std::string::npos || line[0] == '#')
    {
      continue;
    }
    if (line[0] == '[')
    {
      const size_t close = line.find(']');
      TraceEntry entry;
      if (close == std::string::npos || !parseStamp(line.substr(1, close - 1), entry.time))
      {
        fail("no time in brackets");
      }
      const std::string rest = line.substr(close + 1);
      if (rest.find("Written data") != std::string::npos)
      {
        entry.direction = TraceDirection::kWritten;
      }
      else if (rest.find("Read data") != std::string::npos)
      {
        entry.direction = TraceDirection::kRead;
      }
      else
      {
        fail(R"(neither "Written data" nor "Read data")");
      }
      entries.push_back(entry);
      continue;
    }
    if (entries.empty() || line.compare(0, 4, "    ") != 0)
    {
      fail("bytes outside an entry");
    }
    std::istringstream hex(line.substr(0, std::min(line.size(), kHexEnd)));
    std::string token;
    while (hex >> token)
    {
      uint8_t byte = 0;
      if (!parseHexPair(token, byte))
      {
        fail("'" + token + "' is not a hex byte");
      }
      entries.back().bytes.push_back(byte);
    }
  }
  return entries;
}

// ---------------------------------------------------------------------------------------------
// Replaying

namespace
{
/// Consecutive chunks this side wrote are one expectation: the program under test may hand the
/// same bytes to its link in other pieces.
std::vector<TraceEntry> mergeWrites(std::vector<TraceEntry> entries)
{
  std::vector<TraceEntry> merged;
  for (auto& entry : entries)
  {
    if (!merged.empty() && entry.direction == TraceDirection::kWritten &&
        merged.back().direction == TraceDirection::kWritten)
    {
      merged.back().bytes.insert(merged.back().bytes.end(), entry.bytes.begin(), entry.bytes.end());
      merged.back().time = entry.time;
      continue;
    }
    merged.push_back(std::move(entry));
  }
  return merged;
}
}  // namespace

TraceReplay::TraceReplay(std::vector<TraceEntry> entries, Options options)
    : entries_(mergeWrites(std::move(entries))), options_(options)
{
  if (!(options_.speed > 0.0) || options_.speed > 1000.0)
  {
    throw ConfigError("the replay speed must be above 0 and at most 1000 (1: as recorded)");
  }
}

bool TraceReplay::expect(Transport& link, const std::vector<uint8_t>& wanted, Milliseconds limit, ReplayResult& result)
{
  const auto deadline = std::chrono::steady_clock::now() + limit;
  size_t matched = 0;
  while (matched < wanted.size())
  {
    const auto left = std::chrono::duration_cast<Milliseconds>(deadline - std::chrono::steady_clock::now());
    uint8_t byte = 0;
    if (left.count() <= 0 || link.read(&byte, 1, left) == 0)
    {
      result.message = "the program sent " + std::to_string(matched) + " of the " + std::to_string(wanted.size()) +
                       " bytes the trace expects next (next: " + hexOf(wanted[matched]) + ") within " +
                       std::to_string(limit.count()) + " ms";
      return false;
    }
    if (byte != wanted[matched])
    {
      result.message = "the program sent " + hexOf(byte) + " where the trace has " + hexOf(wanted[matched]) +
                       " (byte " + std::to_string(matched + 1) + " of " + std::to_string(wanted.size()) + ")";
      return false;
    }
    ++matched;
    ++result.bytes_checked;
  }
  return true;
}

ReplayResult TraceReplay::run(Transport& link, const Progress& progress)
{
  ReplayResult result;
  if (entries_.empty())
  {
    result.message = "the trace has no entries";
    return result;
  }
  double last_recorded = entries_.front().time;
  auto last_actual = std::chrono::steady_clock::now();
  for (const auto& entry : entries_)
  {
    const auto gap = std::chrono::duration_cast<Milliseconds>(
        std::chrono::duration<double>(std::max(0.0, entry.time - last_recorded) / options_.speed));
    if (entry.direction == TraceDirection::kRead)
    {
      std::this_thread::sleep_until(last_actual + gap);  // the far side's own pace, as recorded
      link.write(entry.bytes.data(), entry.bytes.size());
      link.drain();
      result.bytes_sent += entry.bytes.size();
    }
    else if (!expect(link, entry.bytes, gap + options_.host_slack, result))
    {
      result.message = "entry " + std::to_string(result.entries + 1) + " of " + std::to_string(entries_.size()) + ": " +
                       result.message;
      return result;
    }
    ++result.entries;
    last_recorded = entry.time;
    last_actual = std::chrono::steady_clock::now();
    if (progress)
    {
      progress(std::string(entry.direction == TraceDirection::kRead ? "sent " : "matched ") +
               std::to_string(entry.bytes.size()) + " bytes (entry " + std::to_string(result.entries) + " of " +
               std::to_string(entries_.size()) + ")");
    }
  }
  std::vector<uint8_t> extra(256);
  const size_t more = link.read(extra.data(), extra.size(), options_.quiet_after);
  if (more > 0)
  {
    result.message =
        "the program sent " + std::to_string(more) + " bytes after the trace's end (first: " + hexOf(extra[0]) + ")";
    return result;
  }
  result.matched = true;
  result.message = "replayed " + std::to_string(result.entries) + " entries: sent " +
                   std::to_string(result.bytes_sent) + " bytes, the program answered all " +
                   std::to_string(result.bytes_checked) + " bytes as recorded";
  return result;
}
}  // namespace cnc_bridge
