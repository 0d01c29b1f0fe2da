// libFuzzer target: arbitrary bytes split at arbitrary points into the ethernut stream decoder.
// Every complete frame must decode to finite fields or be rejected with ProtocolError; the
// decoder must never hold more than one partial frame after being drained.
#include <cmath>
#include <cstdlib>

#include "cnc_bridge/ethernut/protocol.h"

using namespace cnc_bridge::ethernut;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  if (size == 0)
  {
    return 0;
  }
  // The first byte chooses the read size, so splits vary with the input.
  const size_t chunk = 1 + data[0] % 64;
  StreamDecoder decoder;
  size_t frames = 0;
  for (size_t at = 1; at < size;)
  {
    const size_t n = std::min(chunk, size - at);
    const size_t taken = decoder.feed(data + at, n);
    at += taken;
    for (;;)
    {
      Message m;
      try
      {
        if (!decoder.next(m))
        {
          break;
        }
        if (!std::isfinite(m.x) || !std::isfinite(m.status) || !std::isfinite(m.error))
        {
          std::abort();
        }
        (void)classify(m);
        (void)describe(m);
        // A decoded message re-encodes to itself.
        const Frame f = encode(m);
        if (decode(f.data()).status != m.status)
        {
          std::abort();
        }
      }
      catch (const cnc_bridge::ProtocolError&)
      {
      }
      ++frames;
    }
    if (decoder.pending() >= kMessageSize)
    {
      std::abort();
    }
  }
  if (frames != (size - 1) / kMessageSize)
  {
    std::abort();
  }
  return 0;
}
