// libFuzzer target: the XModem packet parser on arbitrary bytes (both check types), then a whole
// receiver session on a scripted link that delivers the input and then goes away. Neither may
// crash, read out of bounds or loop; errors are cnc_bridge::Error.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/xmodem/file_transfer.h"
#include "cnc_bridge/xmodem/packet.h"
#include "cnc_bridge/xmodem/session.h"
#include "testing/fake_transport.h"

using namespace cnc_bridge;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  for (xmodem::CheckType check : {xmodem::CheckType::kChecksum, xmodem::CheckType::kCrc16})
  {
    const xmodem::Packet packet = xmodem::decodePacket(data, size, check);
    if (packet.status == xmodem::PacketStatus::kOk)
    {
      volatile uint8_t sink = packet.data[packet.data_size - 1];  // must be inside the input
      (void)sink;
    }
  }

  FakeTransport link("fuzz");
  link.feed(std::vector<uint8_t>(data, data + size));
  link.disconnect();
  xmodem::Config config;
  config.nak_interval = config.block_timeout = config.char_timeout = Milliseconds(1);
  config.purge_quiet = config.eot_quiet = Milliseconds(1);
  config.start_timeout = Milliseconds(5);
  xmodem::Receiver receiver(link, size % 2 ? xmodem::Mode::kCrc : xmodem::Mode::kChecksum, config);
  try
  {
    std::vector<uint8_t> payload = receiver.receive();
    xmodem::TextOptions text;
    text.control_eob = static_cast<xmodem::Eob>(size % 5);
    xmodem::fromWire(std::move(payload), text);
  }
  catch (const Error&)
  {
  }
  return 0;
}
