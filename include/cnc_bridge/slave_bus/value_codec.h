// Integer values in slave payloads. The universal-CNC paper's slaves (docs/protocols/slave_bus.md#source) take
// plain bytes, and two-byte values as hi * 100 + lo (its slave loop reads recived[0]*100+recived[1]); a big-endian
// 16-bit form is the usual alternative. Each slave picks one encoding; the node and the simulator share this codec.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace cnc_bridge
{
namespace slave_bus
{
/// \brief How a slave's integer values are laid out in its payload. Every value has the same width.
enum class Encoding
{
  kBytes,        ///< one byte per value, 0..255
  kHundreds,     ///< two bytes [hi, lo], value = hi * 100 + lo, lo < 100: 0..25599 (the universal-CNC paper's form)
  kBigEndian16,  ///< two bytes, unsigned, most significant first: 0..65535
  kBigEndian16s  ///< two bytes, two's complement, most significant first: -32768..32767
};

/// \brief "bytes" | "hundreds" | "be16" | "be16s". \throws ConfigError for anything else.
Encoding parseEncoding(const std::string& text);
const char* toString(Encoding encoding);
/// \returns bytes per value: 1 or 2.
size_t valueWidth(Encoding encoding);
int32_t minValue(Encoding encoding);
int32_t maxValue(Encoding encoding);

/// \brief Appends \p value to \p out. \throws ProtocolError if it is out of the encoding's range.
void encodeValue(int32_t value, Encoding encoding, std::vector<uint8_t>& out);
/// \brief Encodes a list of values. \throws ProtocolError if one is out of range.
std::vector<uint8_t> encodeValues(const std::vector<int32_t>& values, Encoding encoding);
/// \brief Decodes a payload into values.
/// \throws ProtocolError if its length is not a multiple of the width, or (hundreds) a low byte is
/// 100 or more.
std::vector<int32_t> decodeValues(const std::vector<uint8_t>& payload, Encoding encoding);
}  // namespace slave_bus
}  // namespace cnc_bridge
