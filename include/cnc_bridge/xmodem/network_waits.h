// XModem's waits on a serial line at a device server (tcp://, rfc2217://). A device server sends
// what its UART received in chunks (ser2net: 64 characters at a time; other servers may hold up to
// a packet before they send it on) and the network adds its own delay, so a gap inside a packet can
// last a chunk's worth of characters plus a network delay, where a cable never pauses. The node and
// cnc_dnc use these in place of the cable's defaults (30 characters, 30 ms) for a networked port
// unless the user sets the waits.
#pragma once

#include <chrono>

namespace cnc_bridge::xmodem
{
/// Character times of the remote line: a whole 128-byte packet held by the server, and some.
constexpr unsigned kNetworkWaitCharacters = 140;
/// The least wait: a switch or a busy server can hold a segment for tens of milliseconds.
constexpr std::chrono::milliseconds kNetworkWaitFloor{200};
}  // namespace cnc_bridge::xmodem
