// The control characters of paper-tape era NC communication that drip-feed and backup still use
// (Fanuc and Haas alike), and the conversions between a program file's line ends and the end of
// block (EOB) a control expects. Shared by the drip-feed sender, the backup receiver and the
// simulators, so that every side of a test reads the codes the same way.
#pragma once

#include <cstdint>
#include <string>

namespace cnc_bridge
{
namespace dnc
{
/// DC1: "reader start" / XON. The control sends it when it wants (more) program.
constexpr uint8_t kDc1 = 0x11;
/// DC2: "punch on". Sent before a program when the control wants DC codes (Haas setting 14).
constexpr uint8_t kDc2 = 0x12;
/// DC3: "reader stop" / XOFF. The control sends it when its buffer is full; the host must stop
/// within 10 characters (Fanuc).
constexpr uint8_t kDc3 = 0x13;
/// DC4: "punch off". Sent after a program when the control wants DC codes.
constexpr uint8_t kDc4 = 0x14;
constexpr uint8_t kPercent = '%';

/// \brief Drops the parity bit. A control on 7 data bits + even parity (ISO) seen by a port set to
/// 8N1 delivers DC3 (0x13, three bits set) as 0x93; masking makes both read the same.
constexpr uint8_t maskParity(uint8_t byte)
{
  return static_cast<uint8_t>(byte & 0x7F);
}

/// \brief The byte with bit 7 set so that the 8 bits have even parity: what a 7E1 line carries
/// when it is read as 8 data bits (the simulators use it to act like a 7E1 control on a pty).
constexpr uint8_t withEvenParity(uint8_t byte)
{
  uint8_t ones = 0;
  for (uint8_t b = static_cast<uint8_t>(byte & 0x7F); b != 0; b = static_cast<uint8_t>(b >> 1))
  {
    ones = static_cast<uint8_t>(ones + (b & 1));
  }
  return static_cast<uint8_t>((byte & 0x7F) | ((ones & 1) ? 0x80 : 0x00));
}

/// \brief Parses an end-of-block name: "lf" (ISO, Fanuc), "cr" (EIA, some Haas setups), "crlf"
/// (Haas default), "lfcr", "lfcrcr" (some older Fanuc punch formats).
/// \returns the bytes to send at each end of block.
/// \throws ConfigError naming the accepted values.
std::string parseEob(const std::string& name);

/// \brief "lf", "crlf", ... for messages; the escaped bytes if it is none of the named ones.
std::string eobName(const std::string& eob);
}  // namespace dnc
}  // namespace cnc_bridge
