// Integer value encodings of slave payloads (see value_codec.h).
#include "cnc_bridge/slave_bus/value_codec.h"

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace slave_bus
{
Encoding parseEncoding(const std::string& text)
{
  if (text == "bytes")
  {
    return Encoding::kBytes;
  }
  if (text == "hundreds")
  {
    return Encoding::kHundreds;
  }
  if (text == "be16")
  {
    return Encoding::kBigEndian16;
  }
  if (text == "be16s")
  {
    return Encoding::kBigEndian16s;
  }
  throw ConfigError("encoding '" + text + "' is not one of bytes, hundreds, be16, be16s");
}

const char* toString(Encoding encoding)
{
  switch (encoding)
  {
    case Encoding::kBytes:
      return "bytes";
    case Encoding::kHundreds:
      return "hundreds";
    case Encoding::kBigEndian16:
      return "be16";
    case Encoding::kBigEndian16s:
      return "be16s";
  }
  return "?";
}

size_t valueWidth(Encoding encoding)
{
  return encoding == Encoding::kBytes ? 1 : 2;
}

int32_t minValue(Encoding encoding)
{
  return encoding == Encoding::kBigEndian16s ? -32768 : 0;
}

int32_t maxValue(Encoding encoding)
{
  switch (encoding)
  {
    case Encoding::kBytes:
      return 255;
    case Encoding::kHundreds:
      return 255 * 100 + 99;
    case Encoding::kBigEndian16:
      return 65535;
    case Encoding::kBigEndian16s:
      return 32767;
  }
  return 0;
}

void encodeValue(int32_t value, Encoding encoding, std::vector<uint8_t>& out)
{
  if (value < minValue(encoding) || value > maxValue(encoding))
  {
    throw ProtocolError("value " + std::to_string(value) + " is out of range for encoding " + toString(encoding) +
                        " (" + std::to_string(minValue(encoding)) + ".." + std::to_string(maxValue(encoding)) + ")");
  }
  switch (encoding)
  {
    case Encoding::kBytes:
      out.push_back(static_cast<uint8_t>(value));
      return;
    case Encoding::kHundreds:
      out.push_back(static_cast<uint8_t>(value / 100));
      out.push_back(static_cast<uint8_t>(value % 100));
      return;
    case Encoding::kBigEndian16:
    case Encoding::kBigEndian16s:
    {
      const auto bits = static_cast<uint16_t>(value);  // two's complement for negative values
      out.push_back(static_cast<uint8_t>(bits >> 8));
      out.push_back(static_cast<uint8_t>(bits & 0xFF));
      return;
    }
  }
}

std::vector<uint8_t> encodeValues(const std::vector<int32_t>& values, Encoding encoding)
{
  std::vector<uint8_t> out;
  out.reserve(values.size() * valueWidth(encoding));
  for (const int32_t value : values)
  {
    encodeValue(value, encoding, out);
  }
  return out;
}

std::vector<int32_t> decodeValues(const std::vector<uint8_t>& payload, Encoding encoding)
{
  const size_t width = valueWidth(encoding);
  if (payload.size() % width != 0)
  {
    throw ProtocolError("payload of " + std::to_string(payload.size()) + " bytes is not a whole number of " +
                        toString(encoding) + " values");
  }
  std::vector<int32_t> values;
  values.reserve(payload.size() / width);
  for (size_t i = 0; i < payload.size(); i += width)
  {
    switch (encoding)
    {
      case Encoding::kBytes:
        values.push_back(payload[i]);
        break;
      case Encoding::kHundreds:
        if (payload[i + 1] >= 100)
        {
          throw ProtocolError("hundreds value with low byte " + std::to_string(payload[i + 1]) + " (must be < 100)");
        }
        values.push_back(payload[i] * 100 + payload[i + 1]);
        break;
      case Encoding::kBigEndian16:
        values.push_back((payload[i] << 8) | payload[i + 1]);
        break;
      case Encoding::kBigEndian16s:
        values.push_back(static_cast<int16_t>(static_cast<uint16_t>((payload[i] << 8) | payload[i + 1])));
        break;
    }
  }
  return values;
}
}  // namespace slave_bus
}  // namespace cnc_bridge
