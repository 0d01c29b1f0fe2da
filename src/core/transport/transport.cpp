// Transport conveniences shared by every implementation.
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
const char* toString(LinkState state)
{
  switch (state)
  {
    case LinkState::kDown:
      return "down";
    case LinkState::kConnecting:
      return "connecting";
    case LinkState::kUp:
      return "up";
  }
  return "?";
}

int Transport::readByte(Milliseconds timeout)
{
  uint8_t byte = 0;
  return read(&byte, 1, timeout) == 1 ? byte : -1;
}

size_t Transport::readExactly(uint8_t* buffer, size_t size, Milliseconds per_byte_timeout)
{
  size_t done = 0;
  while (done < size)
  {
    const size_t n = read(buffer + done, size - done, per_byte_timeout);
    if (n == 0)
    {
      break;
    }
    done += n;
  }
  return done;
}

void Transport::write(const std::string& text, Milliseconds timeout)
{
  write(reinterpret_cast<const uint8_t*>(text.data()), text.size(), timeout);
}

void Transport::write(const std::vector<uint8_t>& bytes, Milliseconds timeout)
{
  write(bytes.data(), bytes.size(), timeout);
}

void Transport::writeByte(uint8_t byte, Milliseconds timeout)
{
  write(&byte, 1, timeout);
}

size_t Transport::purge(Milliseconds quiet, Milliseconds limit)
{
  const auto deadline = std::chrono::steady_clock::now() + limit;
  uint8_t scratch[256];
  size_t dropped = 0;
  while (std::chrono::steady_clock::now() < deadline)
  {
    const size_t n = read(scratch, sizeof(scratch), quiet);
    if (n == 0)
    {
      break;
    }
    dropped += n;
  }
  return dropped;
}
}  // namespace cnc_bridge
