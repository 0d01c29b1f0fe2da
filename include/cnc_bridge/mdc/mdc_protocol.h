// The Haas Machine Data Collection (MDC) protocol as text: how queries are written, how replies are
// parsed, which reply answers which query, and how Haas modes and run states map onto the machine
// state every cnc_bridge node publishes. No I/O here (see mdc_client.h), so every rule can be tested
// on strings and fuzzed.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace cnc_bridge
{
namespace mdc
{
/// \brief One request to the control: a `Q` query (with an optional argument, the macro number of
/// Q600) or an `E` write.
///
/// Wire format (Haas "Machine Data Collection", NGC setting 143 = TCP port; Classic: the RS-232 port):
/// the host sends `?Q<nnn>[ <arg>]` and CR LF, e.g. `?Q500\r\n`, `?Q600 5021\r\n`; a write is
/// `?E<var> <value>\r\n`. Codes are three digits; Q600's argument is a macro or system variable.
struct Query
{
  char letter = 'Q';  ///< 'Q' (read) or 'E' (write a macro variable)
  int code = 0;       ///< 100, 104, 500, 600 ... for Q; the variable number for E
  std::optional<double> argument;

  /// \brief "?Q500", "?Q600 5021", "?E100 1.5": the text sent, without the line end.
  /// \throws ProtocolError if the argument cannot be carried exactly (see writeQuery()).
  std::string text() const;
  bool operator==(const Query& other) const;
};

/// \brief Common queries.
Query q(int code);
Query macroQuery(int variable);  ///< ?Q600 <variable>
/// \brief `?E<variable> <value>`: a macro variable write.
/// \throws ProtocolError naming the value and the reason if the wire cannot carry it exactly: not
/// finite, magnitude 1e15 or more, or more than 6 decimals (1e-7 would arrive as 0). Never rounded.
Query writeQuery(int variable, double value);

/// \brief What a reply line is about, recognised from its first field.
enum class ReplyKind
{
  kSerialNumber,     ///< Q100 "SERIAL NUMBER, 1234567"
  kSoftwareVersion,  ///< Q101 "SOFTWARE VERSION, 100.20.000.1200"
  kModel,            ///< Q102 "MODEL, VF2D"
  kMode,             ///< Q104 "MODE, (MEM)"
  kToolChanges,      ///< Q200 "TOOL CHANGES, 23"
  kToolInUse,        ///< Q201 "USING TOOL, 1"
  kPowerOnTime,      ///< Q300 "P.O. TIME, 00027:50:59"
  kMotionTime,       ///< Q301 "C.S. TIME, 00003:02:57"
  kLastCycle,        ///< Q303 "LAST CYCLE, 000:00:00"
  kPreviousCycle,    ///< Q304 "PREV CYCLE, 000:00:00"
  kPartsCounter1,    ///< Q402 "M30 #1, 553"
  kPartsCounter2,    ///< Q403 "M30 #2, 553"
  kProgramStatus,    ///< Q500 "PROGRAM, O00110, IDLE, PARTS, 4523" or "STATUS, BUSY"
  kMacro,            ///< Q600 "MACRO, 0.0" (NGC, no variable number) or "MACRO, 5021, -1.2345" (Classic)
  kUnknownQuery,     ///< "?, ?Q105" (NGC), "UNKNOWN" or "INVALID NUMBER" (Classic): not understood
  kWriteAck,         ///< "!" after an E command (see docs/haas_mdc_node.md on this reading)
  kOther             ///< a line we do not recognise (kept, counted, never fatal)
};
const char* toString(ReplyKind kind);

/// \brief One parsed reply line.
struct Reply
{
  ReplyKind kind = ReplyKind::kOther;
  std::vector<std::string> fields;  ///< comma-separated fields, trimmed, first one upper-cased
  std::string echoed;               ///< the query the control echoed before the reply, if any ("?Q500")
  std::string line;                 ///< the line as received, without framing
  /// The query this reply was taken to answer (set by MdcClient::request; empty for a reply read
  /// as another client's). An NGC macro reply names no variable, so only this says which it is.
  std::optional<Query> answered;
};

/// \brief Parses one reply line, tolerantly.
///
/// Accepted: the `>` prompt before or after the reply (any number), STX/ETB framing bytes of the
/// Classic serial port, an echo of the query before the reply (`?Q500 PROGRAM, ...` or a line of
/// its own), spaces around fields and commas, lower case, keys written without their inner spaces
/// ("C.S.TIME"), a trailing full stop ("UNKNOWN."), "STATUS BUSY" without its comma. The replies
/// seen from real controls are in test/data/mdc/ (README.md there names their sources).
/// \returns nullopt for a line with nothing in it (a bare prompt, an echo alone).
std::optional<Reply> parseReply(const std::string& line);

/// \brief Whether \p reply answers \p query. Replies are matched by content, not by order: a second
/// MDC client's replies arrive on our connection too. A Classic Q600 reply matches on its variable
/// number; an NGC one ("MACRO, value") names none and so matches any Q600. "?, ?Q105" matches the
/// query it names; a rejection that names none ("UNKNOWN") matches any query.
bool answers(const Query& query, const Reply& reply);

/// \brief The Q code a reply kind answers (100 for kSerialNumber ...); 0 for none.
int queryCodeOf(ReplyKind kind);

/// \brief Q500 decoded.
struct ProgramStatus
{
  std::string program;           ///< "O00110"; empty while BUSY (the control does not say)
  std::string status;            ///< "IDLE", "BUSY", "FEED HOLD", "ALARM ON" ... as sent, upper case
  std::optional<int64_t> parts;  ///< the M30 counter, absent while BUSY
};

/// \throws ProtocolError if \p reply is not a Q500 reply or a number does not parse.
ProgramStatus toProgramStatus(const Reply& reply);
/// \returns the value after the key ("SERIAL NUMBER, 1234567" -> "1234567"). \throws ProtocolError.
std::string valueOf(const Reply& reply);
/// \returns the number after the key as an integer ("USING TOOL, 1" -> 1). \throws ProtocolError.
int64_t integerOf(const Reply& reply);
/// \brief A Q600 reply decoded.
struct MacroReading
{
  std::optional<int> variable;  ///< from the reply (Classic) or from Reply::answered (NGC); absent if neither
  double value = 0.0;
};
/// \brief Q600: variable number (when known) and value. \throws ProtocolError.
MacroReading macroOf(const Reply& reply);
/// \brief "00027:50:59" or "000:00:00" (hours:minutes:seconds; hours may be long) -> seconds.
/// \throws ProtocolError.
double parseDuration(const std::string& text);
/// \brief Parses a decimal number, whole text, no locale. \throws ProtocolError.
double parseNumber(const std::string& text);

/// \brief Execution state, the same values as cnc_bridge/MachineState EXECUTION_*.
enum class Execution : uint8_t
{
  kUnknown = 0,
  kReady = 1,
  kActive = 2,
  kPaused = 3,
  kStopped = 4,
  kAlarm = 5
};
/// \brief Mode, the same values as cnc_bridge/MachineState MODE_*.
enum class Mode : uint8_t
{
  kUnknown = 0,
  kAuto = 1,
  kManual = 2,
  kMdi = 3,
  kDnc = 4,
  kEdit = 5,
  kHoming = 6
};

/// \brief Haas Q500 status -> execution, as MTConnect adapters read it: IDLE -> READY,
/// BUSY -> ACTIVE, FEED HOLD -> PAUSED, anything with ALARM -> ALARM, STOP -> STOPPED.
Execution mapExecution(const std::string& status);
/// \brief Haas Q104 mode ("(MEM)", "MDI", "ZERO RET") -> mode: MEM -> AUTO, MDI -> MDI,
/// JOG/HAND JOG/HANDLE -> MANUAL, ZERO RET -> HOMING, EDIT/LIST PROG -> EDIT, DNC -> DNC.
Mode mapMode(const std::string& mode);
const char* toString(Execution execution);
const char* toString(Mode mode);

/// \brief Whether \p text is a read-only query a user may send raw: `?Q<3 digits>` with at most
/// one numeric argument, printable ASCII only. E commands and anything else are refused.
/// \returns the parsed query, or nullopt.
std::optional<Query> parseReadOnlyQuery(const std::string& text);

/// \brief Longest reply line accepted; longer ones are dropped and counted (a babbling line
/// cannot grow memory without bound). Real replies are under 80 characters.
constexpr size_t kMaxLineLength = 512;
}  // namespace mdc
}  // namespace cnc_bridge
