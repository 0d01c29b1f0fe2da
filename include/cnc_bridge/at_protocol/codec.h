// The '@'-protocol of the ESPRIT add-in and its real-time Linux controller (docs/protocols/at_protocol.md;
// the ESPRIT paper's section 4.2): the messages in both directions as plain structs,
// their text encoding, and the reassemblers that cut a TCP byte stream back into messages. The
// controller side only sees a byte stream, which is why every PC -> controller message ends in '@';
// the controller -> PC side is line based.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace cnc_bridge
{
namespace at_protocol
{
/// Pulses per millimetre on every axis (the ESPRIT paper, 4.2: "there are 1000 pulses in 1 millimetre").
constexpr double kPulsesPerMm = 1000.0;
/// Pulses per metre, for the SI conversion in the ROS layer.
constexpr double kPulsesPerMetre = 1.0e6;
/// Largest magnitude of a setpoint feed value and of the spindle and jog feed values.
constexpr int kMaxFeed = 255;
/// Longest message either side accepts (a setpoint with six 11-digit numbers is about 80 bytes).
constexpr size_t kMaxMessageLength = 128;

enum class Axis : uint8_t
{
  kX = 0,
  kY = 1,
  kZ = 2
};
char toChar(Axis axis);
/// \brief 'X', 'Y', 'Z' (either case) to an axis. \throws ProtocolError for anything else.
Axis axisFromChar(char c);

// ---- PC -> controller ------------------------------------------------------------------------

/// `A@`: switch to auto mode.
struct AutoMode
{
};
/// `J<axis>@`: switch to jog mode on one axis.
struct JogMode
{
  Axis axis = Axis::kX;
};
/// `M1@` start of the whole machining, `M0@` its end (the controller then stops the spindle).
struct Machining
{
  bool start = false;
};
/// `P1@` / `P0@`: an operation starts, with / without coolant; setpoints follow.
struct StartOperation
{
  bool coolant = false;
};
/// `S<0..255>@`: spindle speed, clockwise only.
struct Spindle
{
  int speed = 0;
};
/// `F<0..255>@`: jog feedrate, used by every axis in jog mode.
struct JogFeed
{
  int feed = 0;
};
/// `T<n> <length>@`: tool change; length in whole millimetres.
struct ToolChange
{
  int tool = 0;
  int length_mm = 0;
};
/// `H@`: go to the home position.
struct Home
{
};
/// `<fx> <px> <fy> <py> <fz> <pz>@`: the setpoint of one 1 ms time step.
struct Setpoint
{
  std::array<int, 3> feed{};          ///< -255..255 per axis; the sign is the direction
  std::array<int32_t, 3> position{};  ///< pulses (1/1000 mm) per axis
  bool operator==(const Setpoint& other) const { return feed == other.feed && position == other.position; }
};
/// `#@`: the last setpoint of an operation has been sent.
struct EndOperation
{
};

using Command = std::variant<AutoMode, JogMode, Machining, StartOperation, Spindle, JogFeed, ToolChange, Home, Setpoint,
                             EndOperation>;

/// \brief The 0..255 value of \p value on a scale whose 255 stands for \p full_scale (spindle
/// rev/min over ~spindle_max_rpm, jog mm/s over the axis' top speed), rounded to the nearest step
/// of full_scale / 255 (the protocol's resolution; the caller reports the value sent).
/// \throws ProtocolError naming \p what and the range if \p value is not finite or outside
/// 0..full_scale: never clamped, wrapped or zeroed.
int scaledValue(double value, double full_scale, const std::string& what);

/// \brief The tool change `T<tool> <length>@` for a length in metres.
/// \throws ProtocolError naming the reason if the tool is outside 0..9999 or the length is not
/// finite, outside 0..10 m or not a whole millimetre (the wire carries whole millimetres; a length
/// is never rounded or wrapped to fit).
ToolChange toolChangeFor(int64_t tool, double length_m);

/// \brief The wire text of a command, '@' included, e.g. "S150@", "12 3400 -5 100 0 0@".
/// \throws ProtocolError if a value is out of range (so nothing out of range ever leaves).
std::string encode(const Command& command);

/// \brief Appends the wire text of a setpoint to \p out without allocating when \p out has room.
/// This is the hot path of the 1 ms sender. \throws ProtocolError on an out-of-range feed.
void appendSetpoint(const Setpoint& setpoint, std::string& out);

/// \brief Decodes one message without its '@' (as CommandReassembler hands it out).
/// \throws ProtocolError naming the message and what is wrong with it.
Command decodeCommand(std::string_view message);

/// \brief A short human name of a command for logs and refusals: "jog mode X", "setpoint".
std::string describe(const Command& command);

/// \brief Cuts the controller's byte stream into messages at '@'. Not thread-safe.
///
/// Bytes arrive in arbitrary pieces (TCP): a message may be split over reads and one read may hold
/// several. Leading whitespace (CR/LF a terminal adds) is dropped. A message longer than
/// kMaxMessageLength is an error: it is reported once and its bytes are skipped up to the next '@',
/// so one garbled message never swallows the valid ones after it.
class CommandReassembler
{
 public:
  struct Result
  {
    std::vector<std::string> messages;  ///< complete messages, '@' removed
    std::vector<std::string> errors;    ///< what was dropped and why
  };
  Result feed(const uint8_t* data, size_t size);
  Result feed(std::string_view text) { return feed(reinterpret_cast<const uint8_t*>(text.data()), text.size()); }
  /// Bytes of an incomplete message held back.
  size_t pending() const { return buffer_.size(); }

 private:
  std::string buffer_;
  bool overflow_ = false;
};

// ---- controller -> PC ------------------------------------------------------------------------

/// `E1` emergency stop active, `E0` released.
struct EStopReport
{
  bool active = false;
};
/// `A`: the controller is in auto mode.
struct AutoModeReport
{
};
/// `JX`/`JY`/`JZ`: the controller is in jog mode on that axis.
struct JogModeReport
{
  Axis axis = Axis::kX;
};
/// `PosX PosY PosZ`: the measured position in pulses.
struct PositionReport
{
  std::array<int32_t, 3> position{};
};
/// `H`: the machine is at its home position.
struct HomeReport
{
};

using Report = std::variant<EStopReport, AutoModeReport, JogModeReport, PositionReport, HomeReport>;

/// \brief The wire text of a report with its line end, e.g. "E1\n", "45334 34623 54934\n".
std::string encode(const Report& report);

/// \brief Parses one report line (without its line end; surrounding blanks are ignored).
/// \throws ProtocolError naming the line and what is wrong with it.
Report parseReport(std::string_view line);

/// \brief Cuts the report stream into lines at LF, CR or CR LF; blank lines are skipped; an
/// overlong line is reported once and skipped up to its line end. Not thread-safe.
class LineReassembler
{
 public:
  using Result = CommandReassembler::Result;
  Result feed(const uint8_t* data, size_t size);
  Result feed(std::string_view text) { return feed(reinterpret_cast<const uint8_t*>(text.data()), text.size()); }
  size_t pending() const { return buffer_.size(); }

 private:
  std::string buffer_;
  bool overflow_ = false;
};
}  // namespace at_protocol
}  // namespace cnc_bridge
