// The ethernut board's message: one fixed 20-byte struct of five floats, and the 18-row opcode
// table that gives the pair (status, x) its meaning. This file holds the codec (bytes <-> struct),
// a stream decoder for a TCP byte stream, and the opcode table; the client session is in client.h.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace ethernut
{
/// \brief One protocol message, as qCNC's `typedef struct { float x, y, z, status, error; }
/// protocol;` (qCNC developer documentation, section 3.1 and Interfaces.h).
///
/// Wire format, 20 bytes, no header, no checksum, no delimiter:
///
///     offset 0  float32 x       coordinates: mm; in commands the second half of the opcode
///     offset 4  float32 y
///     offset 8  float32 z
///     offset 12 float32 status  first half of the opcode (1 coordinates, 4 position, 15 mode, ...)
///     offset 16 float32 error   0-9 "internal error management"; we send 0
///
/// Each float is IEEE-754 binary32, little-endian: the board is an ATmega128 (avr-gcc stores
/// float as little-endian binary32) and the PC side sent the struct's memory as is from an x86
/// PC, so both ends agree on little-endian. We encode explicitly so a big-endian host also works.
struct Message
{
  float x = 0.0f;
  float y = 0.0f;
  float z = 0.0f;
  float status = 0.0f;
  float error = 0.0f;
};

constexpr size_t kMessageSize = 20;
using Frame = std::array<uint8_t, kMessageSize>;

/// \brief The opcode table (docs/protocols/ethernut.md#opcode-table), one enumerator per row, in row order.
enum class Opcode : uint8_t
{
  kCoordinates = 1,     ///< status 1: a set of coordinates (PC -> board); answered NEXT/RESEND
  kSyncOled = 2,        ///< status 2: sync coordinates to the oLED (PC -> board); ack
  kCommand = 3,         ///< status 3: TCP/serial specific command (PC -> board); ack
  kPosition = 4,        ///< status 4: position from the board (board -> PC); we ack it
  kFileMode = 5,        ///< (15, 15) file transaction mode; ack
  kGuiControlMode = 6,  ///< (15, 6) coordinates taken from the GUI's controls; ack
  kStandaloneMode = 7,  ///< (15, 9) standalone: the board drops TCP clients; ack
  kReset = 8,           ///< (99, 0) reset/clear memory, set the CNC to 0/0/0; ack
  kKill = 9,            ///< (99, 99) kill: stop all activity and disconnect; ack
  kPauseRequest = 10,   ///< (99, 199) pause request (PC -> board); answered by row 11
  kPauseAchieved = 11,  ///< (99, 201) pause achieved (board -> PC)
  kNext = 12,           ///< (200, 30) coordinates OK, send the next set (board -> PC)
  kReadyToSend = 13,    ///< (200, 50) READYTOSEND request (PC -> board); ack
  kResend = 14,         ///< (200, 60) coordinates error, resend (board -> PC)
  kInitRequest = 15,    ///< (200, 78) init request / connection ok? (PC -> board); ack
  kAck = 16,            ///< (200, 101) global acknowledge (either way)
  kAliveRequest = 17,   ///< (200, 199) alive request (PC -> board); answered by row 18
  kAliveResponse = 18,  ///< (200, 999) connection still alive (board -> PC)
  kUnknown = 0          ///< no row matches
};

/// \brief One row of the opcode table.
struct OpcodeRow
{
  Opcode opcode;
  int status;        ///< value of protocol::status
  int x;             ///< value of protocol::x, or kAnyX when x carries a coordinate
  const char* name;  ///< short name for logs and diagnostics ("NEXT", "pause-achieved", ...)
  bool from_board;   ///< true if the board sends it (Origin "ethernut"/"TCP")
  Opcode response;   ///< what answers it (kUnknown: nothing)
};
constexpr int kAnyX = -1;

/// \brief The 18 rows, in table order (opcodeTable()[i].opcode == Opcode(i + 1)).
const std::array<OpcodeRow, 18>& opcodeTable();
/// \brief The row of \p opcode. \throws ProtocolError for kUnknown.
const OpcodeRow& rowOf(Opcode opcode);
/// \brief Short name of \p opcode ("unknown" for kUnknown).
const char* toString(Opcode opcode);

/// \brief The opcode a message carries: status 1..4 alone, otherwise the pair (status, x).
/// Values must be whole numbers; anything else is kUnknown.
Opcode classify(const Message& message);

/// \brief A message carrying \p opcode; \p x, \p y, \p z are used only by the coordinate rows
/// (status 1-4), for the others x is the opcode's second half and y = z = 0.
Message makeMessage(Opcode opcode, float x = 0.0f, float y = 0.0f, float z = 0.0f);

/// \brief Encodes \p message into 20 bytes (little-endian binary32).
/// \throws ProtocolError if a field is NaN or infinite (the board cannot act on it).
Frame encode(const Message& message);
void encode(const Message& message, uint8_t* out);

/// \brief Decodes 20 bytes.
/// \throws ProtocolError naming the field if it is NaN or infinite.
Message decode(const uint8_t* bytes);

/// \brief Cuts a TCP byte stream into messages: bytes arrive in any split (a message over
/// several reads, several messages in one read). There is no sync marker in the protocol, so
/// framing is by count from the start of the connection; a frame with a NaN/inf field is consumed
/// (framing stays aligned) and reported. Not thread-safe.
class StreamDecoder
{
 public:
  /// \brief Appends received bytes; call next() until it returns false before feeding more.
  /// \returns the number of bytes taken (all of them when next() was drained before).
  size_t feed(const uint8_t* data, size_t size);
  /// \brief Takes the next complete message.
  /// \returns false if no complete message is buffered.
  /// \throws ProtocolError for a frame with a non-finite field (the frame is dropped).
  bool next(Message& message);
  /// \brief Bytes of an incomplete message held back.
  size_t pending() const { return size_; }
  void clear()
  {
    size_ = 0;
    start_ = 0;
  }

 private:
  // Room for many frames so a burst is decoded from one read without moving bytes per frame.
  static constexpr size_t kCapacity = kMessageSize * 64;
  std::array<uint8_t, kCapacity> buffer_{};
  size_t start_ = 0;
  size_t size_ = 0;
};

/// \brief "status=200 x=30 (NEXT)" for logs.
std::string describe(const Message& message);
}  // namespace ethernut
}  // namespace cnc_bridge
