// libFuzzer target: the simulated master (the receive state machine of the universal-CNC paper,
// docs/protocols/slave_bus.md#source, WirePacker to the slaves, the slaves' value decoding) on arbitrary bytes from the
// PC, raw and framed. Invariant: no crash, and whatever it writes up the link parses as whole uplink records.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "cnc_bridge/common/log.h"
#include "sim/slave_bus/sim_master.h"
#include "testing/fake_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::slave_bus;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  if (size < 1)
  {
    return 0;
  }
  const size_t chunk = 1 + data[0] % 16;
  ++data;
  --size;
  setLogHandler([](LogLevel, const std::string&) {});
  for (const Framing framing : {Framing::kRaw, Framing::kFramed})
  {
    FakeTransport link;
    std::vector<SimSlave> slaves = {
        SimSlave(1, SimRole::kAxis, Encoding::kBigEndian16s), SimSlave(2, SimRole::kAxis, Encoding::kHundreds),
        SimSlave(3, SimRole::kTool, Encoding::kBytes), SimSlave(4, SimRole::kGeneric, Encoding::kBytes)};
    SimMaster::Options options;
    options.framing = framing;
    SimMaster master(link, std::move(slaves), options);
    for (size_t i = 0; i < size; i += chunk)
    {
      master.processInput(data + i, std::min(chunk, size - i));
      master.pollSlaves();
    }
    const auto written = link.written();
    UplinkParser parser(framing, kMaxSlaves);
    parser.feed(written.data(), written.size());
    if (parser.pending() != 0 || parser.stats().garbage_bytes != 0)
    {
      std::abort();  // the master wrote something that is not a whole record
    }
  }
  return 0;
}
