// WirePacker framing and its stream unpacker (see wire_packer.h for the wire format).
#include "cnc_bridge/slave_bus/wire_packer.h"

#include <algorithm>
#include <string>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace slave_bus
{
uint8_t crc8Maxim(const uint8_t* data, size_t size, uint8_t crc)
{
  // Bitwise, LSB first, as the 1-Wire CRC the ESP32 library computes. A 256-entry table would be
  // faster, but frames are at most 255 bytes on a link of at most a few hundred kbit/s.
  for (size_t i = 0; i < size; ++i)
  {
    crc ^= data[i];
    for (int bit = 0; bit < 8; ++bit)
    {
      crc = (crc & 0x01) ? static_cast<uint8_t>((crc >> 1) ^ 0x8C) : static_cast<uint8_t>(crc >> 1);
    }
  }
  return crc;
}

WireCrc parseWireCrc(const std::string& text)
{
  if (text == "spec")
  {
    return WireCrc::kSpec;
  }
  if (text == "library")
  {
    return WireCrc::kLibrary;
  }
  throw ConfigError("WirePacker CRC '" + text +
                    "' is neither spec (length and data) nor library (data only, as the ESP32_I2C_Slave library "
                    "computes it)");
}

const char* toString(WireCrc crc)
{
  return crc == WireCrc::kSpec ? "spec (length and data)" : "library (data only)";
}

WireFormat WireFormat::of(WireCrc crc, size_t max_data)
{
  if (max_data > kMaxData)
  {
    throw ConfigError("WirePacker: at most " + std::to_string(kMaxData) + " data bytes fit in one frame, not " +
                      std::to_string(max_data));
  }
  WireFormat format;
  format.crc = crc;
  format.max_data = max_data > 0 ? max_data : (crc == WireCrc::kLibrary ? kLibraryMaxData : kMaxData);
  return format;
}

uint8_t WireFormat::crcOf(uint8_t length, const uint8_t* data, size_t size) const
{
  // The library's calc(&length, 1) result is discarded by its update() (see WireCrc in the header):
  // its CRC starts from 0 at the data.
  const uint8_t seed = crc == WireCrc::kSpec ? crc8Maxim(&length, 1) : 0;
  return crc8Maxim(data, size, seed);
}

std::vector<uint8_t> WirePacker::pack(const uint8_t* data, size_t size, const WireFormat& format)
{
  if (size > format.max_data)
  {
    throw ProtocolError("WirePacker: " + std::to_string(size) + " data bytes do not fit in one frame (at most " +
                        std::to_string(format.max_data) +
                        (format.max_data < kMaxData ? ", the configured limit of the master's buffers)" : ")"));
  }
  std::vector<uint8_t> frame;
  frame.reserve(size + kOverhead);
  frame.push_back(kStart);
  frame.push_back(static_cast<uint8_t>(size + kOverhead));
  frame.insert(frame.end(), data, data + size);
  frame.push_back(format.crcOf(frame[1], data, size));
  frame.push_back(kEnd);
  return frame;
}

std::vector<uint8_t> WirePacker::unpack(const uint8_t* frame, size_t size, const WireFormat& format)
{
  if (size < kOverhead)
  {
    throw ProtocolError("WirePacker: frame of " + std::to_string(size) + " bytes is shorter than 4");
  }
  if (frame[0] != kStart)
  {
    throw ProtocolError("WirePacker: frame starts with " + std::to_string(frame[0]) + ", not 0x02");
  }
  if (frame[1] != size)
  {
    throw ProtocolError("WirePacker: length byte says " + std::to_string(frame[1]) + " but the frame has " +
                        std::to_string(size) + " bytes");
  }
  if (size - kOverhead > format.max_data)
  {
    throw ProtocolError("WirePacker: frame length " + std::to_string(size) + " is over the configured " +
                        std::to_string(format.max_data + kOverhead));
  }
  if (frame[size - 1] != kEnd)
  {
    throw ProtocolError("WirePacker: frame ends with " + std::to_string(frame[size - 1]) + ", not 0x04");
  }
  const uint8_t crc = format.crcOf(frame[1], frame + 2, size - kOverhead);
  if (crc != frame[size - 2])
  {
    throw ProtocolError("WirePacker: CRC mismatch (frame " + std::to_string(frame[size - 2]) + ", computed " +
                        std::to_string(crc) + " over " +
                        (format.crc == WireCrc::kSpec ? "length and data" : "data only") + ")");
  }
  return std::vector<uint8_t>(frame + 2, frame + size - 2);
}

std::vector<std::vector<uint8_t>> WireStreamUnpacker::feed(const uint8_t* data, size_t size)
{
  buffer_.insert(buffer_.end(), data, data + size);
  std::vector<std::vector<uint8_t>> frames;
  scan(frames, false);
  return frames;
}

std::vector<std::vector<uint8_t>> WireStreamUnpacker::resync()
{
  std::vector<std::vector<uint8_t>> frames;
  scan(frames, true);
  return frames;
}

void WireStreamUnpacker::scan(std::vector<std::vector<uint8_t>>& frames, bool abandon_incomplete)
{
  size_t pos = 0;  // start of the unexamined part of buffer_
  for (;;)
  {
    const auto start = std::find(buffer_.begin() + static_cast<std::ptrdiff_t>(pos), buffer_.end(), WirePacker::kStart);
    stats_.garbage_bytes += static_cast<uint64_t>(start - (buffer_.begin() + static_cast<std::ptrdiff_t>(pos)));
    pos = static_cast<size_t>(start - buffer_.begin());
    const size_t left = buffer_.size() - pos;
    if (left == 0)
    {
      break;
    }
    const size_t length = left >= 2 ? buffer_[pos + 1] : 0;
    if (left >= 2 && (length < WirePacker::kOverhead || length > format_.max_data + WirePacker::kOverhead))
    {
      // A length no frame of this format has: reject the candidate at once rather than waiting for
      // that many bytes (a stray 0x02 then 0xF0 would otherwise hide 240 bytes of good frames).
      ++stats_.framing_errors;
      ++stats_.garbage_bytes;
      ++pos;
      continue;
    }
    if (left < 2 || left < length)
    {
      if (!abandon_incomplete)
      {
        break;  // incomplete: wait for more
      }
      // The peer fell silent inside this candidate: it is torn (or was never a frame). Drop its
      // start byte only and look again, so that good frames inside it are still found.
      ++stats_.framing_errors;
      ++stats_.garbage_bytes;
      ++pos;
      continue;
    }
    const uint8_t* frame = buffer_.data() + pos;
    if (frame[length - 1] != WirePacker::kEnd)
    {
      ++stats_.framing_errors;
      ++stats_.garbage_bytes;
      ++pos;  // drop this start byte only: a real frame may begin at the next byte
      continue;
    }
    if (format_.crcOf(frame[1], frame + 2, length - WirePacker::kOverhead) != frame[length - 2])
    {
      ++stats_.crc_errors;
      ++stats_.garbage_bytes;
      ++pos;
      continue;
    }
    frames.emplace_back(frame + 2, frame + length - 2);
    ++stats_.frames;
    pos += length;
  }
  buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(pos));
}
}  // namespace slave_bus
}  // namespace cnc_bridge
