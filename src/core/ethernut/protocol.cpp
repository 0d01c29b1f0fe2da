// Codec and opcode table of the ethernut 5-float protocol (see protocol.h for the wire format).
#include "cnc_bridge/ethernut/protocol.h"

#include <cmath>
#include <cstring>
#include <sstream>

namespace cnc_bridge
{
namespace ethernut
{
namespace
{
// Origin/destination per Table 1: rows from "GUI" go PC -> board; "TCP"/"ethernut" rows go
// board -> PC; the global acknowledge (row 16) is "N/A -> N/A" and travels both ways: we mark it
// as from the board because that is where the PC expects it.
const std::array<OpcodeRow, 18> kTable = {{
    {Opcode::kCoordinates, 1, kAnyX, "coordinates", false, Opcode::kNext},
    {Opcode::kSyncOled, 2, kAnyX, "sync-oled", false, Opcode::kAck},
    {Opcode::kCommand, 3, kAnyX, "command", false, Opcode::kAck},
    {Opcode::kPosition, 4, kAnyX, "position", true, Opcode::kAck},
    {Opcode::kFileMode, 15, 15, "file-mode", false, Opcode::kAck},
    {Opcode::kGuiControlMode, 15, 6, "gui-control-mode", false, Opcode::kAck},
    {Opcode::kStandaloneMode, 15, 9, "standalone-mode", false, Opcode::kAck},
    {Opcode::kReset, 99, 0, "reset", false, Opcode::kAck},
    {Opcode::kKill, 99, 99, "kill", false, Opcode::kAck},
    {Opcode::kPauseRequest, 99, 199, "pause-request", false, Opcode::kPauseAchieved},
    {Opcode::kPauseAchieved, 99, 201, "pause-achieved", true, Opcode::kUnknown},
    {Opcode::kNext, 200, 30, "NEXT", true, Opcode::kCoordinates},
    {Opcode::kReadyToSend, 200, 50, "READYTOSEND", false, Opcode::kAck},
    {Opcode::kResend, 200, 60, "RESEND", true, Opcode::kCoordinates},
    {Opcode::kInitRequest, 200, 78, "init-request", false, Opcode::kAck},
    {Opcode::kAck, 200, 101, "ack", true, Opcode::kUnknown},
    {Opcode::kAliveRequest, 200, 199, "alive-request", false, Opcode::kAliveResponse},
    {Opcode::kAliveResponse, 200, 999, "alive-response", true, Opcode::kUnknown},
}};

void putFloat(uint8_t* out, float value)
{
  uint32_t bits = 0;
  std::memcpy(&bits, &value, sizeof bits);
  out[0] = static_cast<uint8_t>(bits);
  out[1] = static_cast<uint8_t>(bits >> 8);
  out[2] = static_cast<uint8_t>(bits >> 16);
  out[3] = static_cast<uint8_t>(bits >> 24);
}

float getFloat(const uint8_t* in)
{
  const uint32_t bits = static_cast<uint32_t>(in[0]) | (static_cast<uint32_t>(in[1]) << 8) |
                        (static_cast<uint32_t>(in[2]) << 16) | (static_cast<uint32_t>(in[3]) << 24);
  float value = 0.0f;
  std::memcpy(&value, &bits, sizeof value);
  return value;
}

const char* const kFieldNames[5] = {"x", "y", "z", "status", "error"};

void checkFinite(const float (&fields)[5], const char* what)
{
  for (int i = 0; i < 5; ++i)
  {
    if (!std::isfinite(fields[i]))
    {
      throw ProtocolError(std::string(what) + ": field " + kFieldNames[i] + " is " +
                          (std::isnan(fields[i]) ? "NaN" : "infinite"));
    }
  }
}

// A float that is exactly a small whole number (opcode halves are).
bool wholeNumber(float value, int& out)
{
  if (!(value >= -1e6f && value <= 1e6f))
  {
    return false;
  }
  const float rounded = std::nearbyint(value);
  if (rounded != value)
  {
    return false;
  }
  out = static_cast<int>(rounded);
  return true;
}
}  // namespace

const std::array<OpcodeRow, 18>& opcodeTable()
{
  return kTable;
}

const OpcodeRow& rowOf(Opcode opcode)
{
  const auto index = static_cast<size_t>(opcode);
  if (index < 1 || index > kTable.size())
  {
    throw ProtocolError("ethernut: no opcode table row for an unknown opcode");
  }
  return kTable[index - 1];
}

const char* toString(Opcode opcode)
{
  const auto index = static_cast<size_t>(opcode);
  return index >= 1 && index <= kTable.size() ? kTable[index - 1].name : "unknown";
}

Opcode classify(const Message& message)
{
  int status = 0;
  if (!wholeNumber(message.status, status))
  {
    return Opcode::kUnknown;
  }
  if (status >= 1 && status <= 4)
  {
    return static_cast<Opcode>(status);
  }
  int x = 0;
  if (!wholeNumber(message.x, x))
  {
    return Opcode::kUnknown;
  }
  for (const OpcodeRow& row : kTable)
  {
    if (row.status == status && row.x == x)
    {
      return row.opcode;
    }
  }
  return Opcode::kUnknown;
}

Message makeMessage(Opcode opcode, float x, float y, float z)
{
  const OpcodeRow& row = rowOf(opcode);
  Message m;
  m.status = static_cast<float>(row.status);
  if (row.x == kAnyX)
  {
    m.x = x;
    m.y = y;
    m.z = z;
  }
  else
  {
    m.x = static_cast<float>(row.x);
  }
  return m;
}

void encode(const Message& message, uint8_t* out)
{
  const float fields[5] = {message.x, message.y, message.z, message.status, message.error};
  checkFinite(fields, "ethernut: cannot send a message");
  for (size_t i = 0; i < 5; ++i)
  {
    putFloat(out + 4 * i, fields[i]);
  }
}

Frame encode(const Message& message)
{
  Frame frame;
  encode(message, frame.data());
  return frame;
}

Message decode(const uint8_t* bytes)
{
  const float fields[5] = {getFloat(bytes), getFloat(bytes + 4), getFloat(bytes + 8), getFloat(bytes + 12),
                           getFloat(bytes + 16)};
  checkFinite(fields, "ethernut: received message rejected");
  Message m;
  m.x = fields[0];
  m.y = fields[1];
  m.z = fields[2];
  m.status = fields[3];
  m.error = fields[4];
  return m;
}

size_t StreamDecoder::feed(const uint8_t* data, size_t size)
{
  if (start_ > 0 && start_ + size_ + size > kCapacity)
  {
    std::memmove(buffer_.data(), buffer_.data() + start_, size_);
    start_ = 0;
  }
  const size_t room = kCapacity - start_ - size_;
  const size_t take = size < room ? size : room;
  std::memcpy(buffer_.data() + start_ + size_, data, take);
  size_ += take;
  return take;
}

bool StreamDecoder::next(Message& message)
{
  if (size_ < kMessageSize)
  {
    if (size_ == 0)
    {
      start_ = 0;
    }
    return false;
  }
  const uint8_t* frame = buffer_.data() + start_;
  start_ += kMessageSize;
  size_ -= kMessageSize;
  message = decode(frame);  // throws after the frame was consumed: framing stays aligned
  return true;
}

std::string describe(const Message& message)
{
  std::ostringstream out;
  out << "status=" << message.status << " x=" << message.x << " y=" << message.y << " z=" << message.z;
  if (message.error != 0.0f)
  {
    out << " error=" << message.error;
  }
  out << " (" << toString(classify(message)) << ")";
  return out.str();
}
}  // namespace ethernut
}  // namespace cnc_bridge
