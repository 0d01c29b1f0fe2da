// A wire trace: every byte a link carries, both directions, with its time, in the form of a serial
// sniffer's dump (docs/protocols/README.md#wire-trace): a header line per chunk as the link
// delivered it, "[time] Written data (link)" for what this side sent and "[time] Read data (link)"
// for what it received, then the bytes 16 to a row, in hex and as text:
//
//   [2026-11-28 08:01:02.123456] Read data (/dev/ttyUSB0@9600)
//       01 01 fe 0a 25 0a 4f 30 35 35 35 35 28 43 53 33   ....%.O05555(CS3
//
// TracingTransport writes one around any link; parseWireTrace() reads it back (and a sniffer's own
// dump, whose times are "[30/10/2017 10:27:21]"); TraceReplay plays a trace's far side against a
// program under test, so that a problem seen in the field becomes a test.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
/// Which way a traced chunk went, seen from the side that traced it.
enum class TraceDirection
{
  kWritten,  ///< this side sent it ("Written data")
  kRead      ///< this side received it ("Read data")
};

/// One chunk of a trace: its direction, when (s, on the trace's own clock) and its bytes.
struct TraceEntry
{
  TraceDirection direction = TraceDirection::kWritten;
  double time = 0.0;
  std::vector<uint8_t> bytes;
};

/// \brief Writes a trace file, bounded in size: past \p max_bytes of traced bytes it writes one
/// line saying so and records nothing more (the link goes on untraced). Thread-safe.
class WireTraceWriter
{
 public:
  /// \throws ConfigError if \p path cannot be created (naming it).
  WireTraceWriter(const std::string& path, const std::string& link, size_t max_bytes);
  ~WireTraceWriter();
  WireTraceWriter(const WireTraceWriter&) = delete;
  WireTraceWriter& operator=(const WireTraceWriter&) = delete;

  void record(TraceDirection direction, const uint8_t* data, size_t size);
  /// A comment line ("# ...") in the trace: a reconnection, the end of the session.
  void note(const std::string& text);

  const std::string& path() const { return path_; }
  size_t tracedBytes() const;

 private:
  std::string path_;
  std::string link_;
  size_t max_bytes_;
  mutable std::mutex mutex_;
  std::unique_ptr<std::ofstream> out_;
  size_t traced_ = 0;
  bool full_ = false;
};

/// \brief A link that traces what passes through it into a WireTraceWriter; otherwise the link
/// it wraps, unchanged. \p Link is Transport, or a richer link interface (SerialLine) whose own
/// calls a subclass forwards to inner().
template <class Link>
class TracingLink : public Link
{
 public:
  TracingLink(std::unique_ptr<Link> link, std::shared_ptr<WireTraceWriter> trace)
      : link_(std::move(link)), trace_(std::move(trace))
  {
  }

  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override
  {
    const size_t n = link_->read(buffer, size, timeout);
    trace_->record(TraceDirection::kRead, buffer, n);
    return n;
  }
  void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override
  {
    link_->write(data, size, timeout);
    trace_->record(TraceDirection::kWritten, data, size);
  }
  using Transport::write;
  void drain() override { link_->drain(); }
  size_t pendingOutput() const override { return link_->pendingOutput(); }
  void discardInput() override { link_->discardInput(); }
  void interrupt() override { link_->interrupt(); }
  void close() override
  {
    link_->close();
    trace_->note("link closed");
  }
  bool isOpen() const override { return link_->isOpen(); }
  std::string describe() const override { return link_->describe(); }

 protected:
  Link& inner() { return *link_; }
  const Link& inner() const { return *link_; }

 private:
  std::unique_ptr<Link> link_;
  std::shared_ptr<WireTraceWriter> trace_;
};
using TracingTransport = TracingLink<Transport>;

/// Where a link's trace goes: off unless dir is set (a parameter ~wire_trace, an option
/// --wire-trace); a file per session of the link in dir, at most max_bytes traced.
struct WireTraceSettings
{
  std::string dir;
  size_t max_bytes = size_t{16} * 1024 * 1024;
  bool enabled() const { return !dir.empty(); }
};

/// \brief Wraps \p link in a trace when \p settings say so (a new file, named after \p name), else
/// returns it as it is. \throws ConfigError if the trace file cannot be created.
template <class Link, class Traced = TracingLink<Link>>
std::unique_ptr<Link> traced(std::unique_ptr<Link> link, const WireTraceSettings& settings, const std::string& name);

/// \brief A trace file's name for one session of a link: DIR/<name>-<UTC time>.trace, \p name made
/// safe for a file name ("/dev/ttyUSB0@9600" -> "dev_ttyUSB0_9600").
std::string wireTracePath(const std::string& dir, const std::string& name,
                          std::chrono::system_clock::time_point when = std::chrono::system_clock::now());

template <class Link, class Traced>
std::unique_ptr<Link> traced(std::unique_ptr<Link> link, const WireTraceSettings& settings, const std::string& name)
{
  if (!settings.enabled())
  {
    return link;
  }
  const std::string description = link->describe();
  auto writer = std::make_shared<WireTraceWriter>(wireTracePath(settings.dir, name), description, settings.max_bytes);
  return std::make_unique<Traced>(std::move(link), std::move(writer));
}

/// \brief Reads a trace (this format or a serial sniffer's dump of the same layout).
/// \throws ConfigError naming \p source and the line for anything that is not a trace.
std::vector<TraceEntry> parseWireTrace(std::istream& in, const std::string& source);

/// How a replay went.
struct ReplayResult
{
  bool matched = false;      ///< the program under test sent what the trace recorded, all of it
  size_t entries = 0;        ///< trace entries played or matched
  size_t bytes_sent = 0;     ///< bytes the replay sent as the far side
  size_t bytes_checked = 0;  ///< bytes of the program under test matched against the trace
  std::string message;       ///< what happened, in words (the divergence when not matched)
};

/// \brief Plays the far side of a trace: sends the bytes this side read ("Read data") at their
/// recorded times, and expects the bytes this side wrote ("Written data") from the program under
/// test, byte for byte.
///
/// Time: a chunk to send waits, after the last event, the gap the trace recorded (divided by
/// speed); expected bytes may take that gap plus host_slack to arrive (a program's own timers, a
/// receiver's first NAK, differ from the recorded one's).
class TraceReplay
{
 public:
  struct Options
  {
    double speed = 1.0;
    Milliseconds host_slack{15000};
    /// After the last entry: how long to listen for bytes the trace does not have.
    Milliseconds quiet_after{500};
  };
  using Progress = std::function<void(const std::string& line)>;

  TraceReplay(std::vector<TraceEntry> entries, Options options);
  /// \brief Plays the trace on \p link (the program under test is at its far end).
  ReplayResult run(Transport& link, const Progress& progress = nullptr);

 private:
  static bool expect(Transport& link, const std::vector<uint8_t>& wanted, Milliseconds limit, ReplayResult& result);
  std::vector<TraceEntry> entries_;
  Options options_;
};
}  // namespace cnc_bridge
