// The host side of a Haas MDC link: sends one query at a time over any Transport (TCP to an NGC
// control on setting 143's port, or the RS-232 port of a Classic control) and waits for the reply
// that answers it. Replies are matched by content, not by order: the control sends every reply to
// both of its MDC connections, so lines meant for another client arrive here too and are handed to
// a listener instead of being taken for ours.
#pragma once

#include <functional>
#include <optional>
#include <string>

#include "cnc_bridge/mdc/mdc_protocol.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
namespace mdc
{
/// \brief Counters of one client, for diagnostics.
struct ClientStats
{
  uint64_t sent = 0;           ///< queries written
  uint64_t answered = 0;       ///< queries that got their reply
  uint64_t unanswered = 0;     ///< queries whose reply did not come within the timeout
  uint64_t rejected = 0;       ///< queries the control answered with "?, ?Qnnn"
  uint64_t foreign = 0;        ///< replies that answered something else (another client, a late reply)
  uint64_t dropped_lines = 0;  ///< lines over kMaxLineLength, dropped
  uint64_t text_lines = 0;     ///< unframed lines handed to the text listener (DPRNT on a shared port)
  double last_latency_ms = 0;  ///< query written to reply read, last answered query
  double max_latency_ms = 0;
  double total_latency_ms = 0;  ///< sum over answered queries (mean = total / answered)
};

/// \brief One MDC conversation over a Transport. Not thread-safe: one thread uses it at a time.
///
/// Wire: `?Q500\r\n` out; in, lines ending in CR, LF or CR LF, each possibly framed by the `>`
/// prompt (and STX/ETB on a Classic serial port), parsed with parseReply().
class MdcClient
{
 public:
  /// \brief Told of every reply that did not answer the query being waited for.
  using ReplyListener = std::function<void(const Reply&)>;

  /// \param transport the link; must outlive the client.
  explicit MdcClient(Transport& transport);

  void setForeignListener(ReplyListener listener) { foreign_listener_ = std::move(listener); }

  /// \brief Told of every line of a shared port that is not an MDC reply.
  using TextListener = std::function<void(const std::string& line)>;

  /// \brief Demultiplexes a Classic control's one RS-232 port, which also carries the DPRNT output
  /// of the running program: with a listener set, only lines holding the STX/ETB framing of a
  /// Classic reply are taken as replies; every other line goes to \p listener, without the `>`
  /// prompt and control bytes (NAKs of a control waiting in RECV, the line end). An echo of a
  /// query (`?Q500`) is no output of the program and is dropped. Unset (the default), every line
  /// is parsed as a reply.
  void setTextListener(TextListener listener) { text_listener_ = std::move(listener); }

  /// \brief Sends \p query and waits for the reply that answers it.
  /// \returns the reply (kind kUnknownQuery if the control did not understand the query).
  /// \throws TimeoutError if no answering reply came within \p timeout; LinkError, CancelledError
  ///         from the transport.
  Reply request(const Query& query, Milliseconds timeout);

  /// \brief request() that throws ProtocolError when the control rejects the query ("?, ?Q105").
  Reply requestValue(const Query& query, Milliseconds timeout);

  /// \brief Reads a macro or system variable with ?Q600.
  /// \throws ProtocolError if rejected or the value does not parse; TimeoutError, LinkError.
  double readVariable(int variable, Milliseconds timeout);

  /// \brief Writes a macro variable with the E command (`?E<var> <value>`). The caller checks the
  /// allow-list (WritePolicy) first.
  /// \throws ProtocolError if the control rejects it; TimeoutError, LinkError.
  void writeVariable(int variable, double value, Milliseconds timeout);

  /// \brief Reads and hands to the listener whatever replies arrive within \p timeout (used between
  /// polls so broadcast replies do not pile up in the input buffer).
  void drainForeign(Milliseconds timeout);

  /// \brief Drops what has arrived but not been read, buffered here and in the transport (bytes of
  /// another protocol that used the line meanwhile, e.g. a DNC transfer).
  void discardInput();

  const ClientStats& stats() const { return stats_; }
  Transport& transport() { return transport_; }

 private:
  /// \returns the next complete line, or false when \p deadline passed first.
  bool readLine(std::string& line, std::chrono::steady_clock::time_point deadline);
  /// \returns the reply \p line holds; nullopt for none, or a text line handed to the listener.
  std::optional<Reply> replyIn(const std::string& line);

  Transport& transport_;
  ReplyListener foreign_listener_;
  TextListener text_listener_;
  std::string partial_;
  bool overflow_ = false;
  ClientStats stats_;
};

/// \brief Which macro variables the host may write. Writes are off unless variables are listed.
/// Thread-safe for concurrent const use.
class WritePolicy
{
 public:
  /// \param allowed variable numbers that may be written.
  /// \param parameter_name what the user sets to change the list (named in refusals).
  WritePolicy(std::vector<int> allowed, std::string parameter_name);

  bool allows(int variable) const;
  /// \throws DisabledError naming the parameter when \p variable is not allowed.
  void check(int variable) const;
  const std::vector<int>& allowed() const { return allowed_; }

 private:
  std::vector<int> allowed_;
  std::string parameter_name_;
};
}  // namespace mdc
}  // namespace cnc_bridge
