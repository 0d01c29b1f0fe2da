// libFuzzer target: the PC's uplink parser (raw and framed) and the WirePacker stream unpacker on
// arbitrary bytes in arbitrary chunks. Invariants: no crash; every record a framed parser returns
// encodes back into a frame that parses to the same record; after resync() nothing is pending.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "cnc_bridge/slave_bus/array_protocol.h"

using namespace cnc_bridge::slave_bus;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  if (size < 2)
  {
    return 0;
  }
  const size_t chunk = 1 + data[0] % 32;  // first byte: chunk size; second: the parser's max address
  const uint8_t max_address = static_cast<uint8_t>(1 + data[1] % kMaxSlaves);
  data += 2;
  size -= 2;
  for (const Framing framing : {Framing::kRaw, Framing::kFramed})
  {
    UplinkParser parser(framing, max_address);
    for (size_t i = 0; i < size; i += chunk)
    {
      const size_t n = std::min(chunk, size - i);
      for (const auto& record : parser.feed(data + i, n))
      {
        if (record.address > max_address || (record.address == 0 && record.payload.empty()))
        {
          std::abort();  // the parser let an impossible record through
        }
        if (framing == Framing::kFramed)
        {
          const auto again = encodeUplink(record, framing);
          UplinkParser check(framing, max_address);
          const auto back = check.feed(again.data(), again.size());
          if (back.size() != 1 || back[0].address != record.address || back[0].payload != record.payload)
          {
            std::abort();
          }
        }
      }
    }
    parser.resync();
    if (parser.pending() != 0)
    {
      std::abort();
    }
  }
  return 0;
}
