// XModem packet framing, check codes and Haas end-of-block conversion (see packet.h).
#include "cnc_bridge/xmodem/packet.h"

#include <array>
#include <stdexcept>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace xmodem
{
namespace
{
// Table-driven CRC-16/XMODEM, one table lookup per byte (the bitwise form costs 8 shifts a byte,
// which shows at 1 MB/s).
std::array<uint16_t, 256> makeCrcTable()
{
  std::array<uint16_t, 256> table{};
  for (unsigned i = 0; i < 256; ++i)
  {
    uint16_t crc = static_cast<uint16_t>(i << 8);
    for (int bit = 0; bit < 8; ++bit)
    {
      crc = (crc & 0x8000) ? static_cast<uint16_t>((crc << 1) ^ 0x1021) : static_cast<uint16_t>(crc << 1);
    }
    table[i] = crc;
  }
  return table;
}
}  // namespace

const char* toString(CheckType check)
{
  return check == CheckType::kCrc16 ? "crc16" : "checksum";
}

uint8_t checksum8(const uint8_t* data, size_t size)
{
  unsigned sum = 0;
  for (size_t i = 0; i < size; ++i)
  {
    sum += data[i];
  }
  return static_cast<uint8_t>(sum & 0xFF);
}

uint16_t crc16Xmodem(const uint8_t* data, size_t size, uint16_t crc)
{
  static const std::array<uint16_t, 256> kTable = makeCrcTable();
  for (size_t i = 0; i < size; ++i)
  {
    crc = static_cast<uint16_t>((crc << 8) ^ kTable[((crc >> 8) ^ data[i]) & 0xFF]);
  }
  return crc;
}

std::vector<uint8_t> encodePacket(uint32_t block, const uint8_t* data, size_t size, size_t block_size, CheckType check)
{
  if (block_size != kBlockSize && block_size != kBlockSize1K)
  {
    throw std::invalid_argument("XModem block size must be 128 or 1024");
  }
  if (size > block_size)
  {
    throw std::invalid_argument("XModem packet data larger than its block");
  }
  std::vector<uint8_t> packet(packetSize(block_size, check), kSub);
  packet[0] = block_size == kBlockSize ? kSoh : kStx;
  packet[1] = static_cast<uint8_t>(block & 0xFF);
  packet[2] = static_cast<uint8_t>(0xFF - packet[1]);
  if (size > 0)
  {
    std::copy(data, data + size, packet.begin() + 3);
  }
  const uint8_t* body = packet.data() + 3;
  if (check == CheckType::kCrc16)
  {
    const uint16_t crc = crc16Xmodem(body, block_size);
    packet[3 + block_size] = static_cast<uint8_t>(crc >> 8);  // high byte first
    packet[4 + block_size] = static_cast<uint8_t>(crc & 0xFF);
  }
  else
  {
    packet[3 + block_size] = checksum8(body, block_size);
  }
  return packet;
}

const char* toString(PacketStatus status)
{
  switch (status)
  {
    case PacketStatus::kOk:
      return "ok";
    case PacketStatus::kTruncated:
      return "truncated packet";
    case PacketStatus::kBadHeader:
      return "bad packet header";
    case PacketStatus::kBadComplement:
      return "block number and complement disagree";
    case PacketStatus::kBadCheck:
      return "check code mismatch";
  }
  return "?";
}

Packet decodePacket(const uint8_t* bytes, size_t size, CheckType check, const ChecksumReading* reading)
{
  Packet packet;
  if (size < 1)
  {
    return packet;
  }
  if (bytes[0] != kSoh && bytes[0] != kStx)
  {
    packet.status = PacketStatus::kBadHeader;
    return packet;
  }
  packet.data_size = bytes[0] == kSoh ? kBlockSize : kBlockSize1K;
  if (size < packetSize(packet.data_size, check))
  {
    packet.status = PacketStatus::kTruncated;
    return packet;
  }
  if (static_cast<uint8_t>(bytes[1] + bytes[2]) != 0xFF)
  {
    packet.status = PacketStatus::kBadComplement;
    return packet;
  }
  packet.block = bytes[1];
  const uint8_t* body = bytes + 3;
  const uint8_t* tail = body + packet.data_size;
  const uint8_t sum = reading != nullptr ? reading->sum(body, packet.data_size) : checksum8(body, packet.data_size);
  const bool good = check == CheckType::kCrc16
                        ? crc16Xmodem(body, packet.data_size) == static_cast<uint16_t>((tail[0] << 8) | tail[1])
                        : sum == tail[0];
  packet.data = body;
  packet.status = good ? PacketStatus::kOk : PacketStatus::kBadCheck;
  return packet;
}

const char* toString(EobChecksum reading)
{
  return reading == EobChecksum::kLf ? "lf" : "wire";
}

EobChecksum parseEobChecksum(const std::string& text)
{
  if (text == "wire")
    return EobChecksum::kWire;
  if (text == "lf")
    return EobChecksum::kLf;
  throw ConfigError("end-of-block checksum reading '" + text +
                    "' is not one of wire (the sum of the bytes on the wire) or lf (each end of block summed as LF)");
}

ChecksumReading::ChecksumReading(EobChecksum reading, Eob eob) : reading_(reading), eob_(eob) {}

uint8_t ChecksumReading::otherSum(const uint8_t* data, size_t size) const
{
  return sumAs(other(), data, size, nullptr);
}

void ChecksumReading::accept(const uint8_t* data, size_t size)
{
  sumAs(EobChecksum::kLf, data, size, &inside_pattern_);
}

uint8_t ChecksumReading::sumAs(EobChecksum reading, const uint8_t* data, size_t size, bool* inside_after) const
{
  const std::string pattern = eobBytes(eob_);
  const auto first = static_cast<uint8_t>(pattern[0]);
  const bool two_bytes = pattern.size() == 2;
  const auto second = static_cast<uint8_t>(pattern.back());
  bool inside = inside_pattern_;
  uint8_t sum = 0;
  for (size_t i = 0; i < size; ++i)
  {
    const uint8_t byte = data[i];
    if (inside && byte == second)
    {
      inside = false;  // the rest of an end of block: nothing in the LF reading
      sum = static_cast<uint8_t>(sum + (reading == EobChecksum::kWire ? byte : 0));
      continue;
    }
    inside = false;
    if (byte == first)
    {
      inside = two_bytes;
      sum = static_cast<uint8_t>(sum + (reading == EobChecksum::kWire ? byte : '\n'));
      continue;
    }
    sum = static_cast<uint8_t>(sum + byte);
  }
  if (inside_after != nullptr)
    *inside_after = inside;
  return sum;
}

const char* toString(Eob eob)
{
  switch (eob)
  {
    case Eob::kLf:
      return "lf";
    case Eob::kCr:
      return "cr";
    case Eob::kCrLf:
      return "crlf";
    case Eob::kCrCr:
      return "crcr";
    case Eob::kLfLf:
      return "lflf";
  }
  return "?";
}

Eob parseEob(const std::string& text)
{
  for (Eob eob : {Eob::kLf, Eob::kCr, Eob::kCrLf, Eob::kCrCr, Eob::kLfLf})
  {
    if (text == toString(eob))
    {
      return eob;
    }
  }
  throw ConfigError("end-of-block pattern '" + text + "' is not one of lf, cr, crlf, crcr, lflf");
}

std::string eobBytes(Eob eob)
{
  switch (eob)
  {
    case Eob::kLf:
      return "\n";
    case Eob::kCr:
      return "\r";
    case Eob::kCrLf:
      return "\r\n";
    case Eob::kCrCr:
      return "\r\r";
    case Eob::kLfLf:
      return "\n\n";
  }
  return "\n";
}

std::string toControlEob(const std::string& text, Eob control)
{
  const std::string eob = eobBytes(control);
  if (eob == "\n" && text.find('\r') == std::string::npos)
  {
    return text;  // the common case (setting 25 = LF ONLY, Unix file): nothing to do
  }
  std::string out;
  out.reserve(text.size() + text.size() / 16);
  for (size_t i = 0; i < text.size(); ++i)
  {
    const char c = text[i];
    if (c == '\r')
    {
      if (i + 1 < text.size() && text[i + 1] == '\n')
      {
        ++i;  // CR LF is one line end
      }
      out += eob;
    }
    else if (c == '\n')
    {
      out += eob;
    }
    else
    {
      out += c;
    }
  }
  return out;
}

std::string fromControlEob(const std::string& text, Eob control, Eob file)
{
  const std::string in = eobBytes(control);
  const std::string out_eob = eobBytes(file);
  if (in == out_eob)
  {
    return text;
  }
  std::string out;
  out.reserve(text.size() + text.size() / 16);
  size_t i = 0;
  while (i < text.size())
  {
    if (text.compare(i, in.size(), in) == 0)
    {
      out += out_eob;
      i += in.size();
    }
    else
    {
      out += text[i++];
    }
  }
  return out;
}

size_t stripSubPadding(std::vector<uint8_t>& data)
{
  while (!data.empty() && data.back() == kSub)
  {
    data.pop_back();
  }
  return data.size();
}
}  // namespace xmodem
}  // namespace cnc_bridge
