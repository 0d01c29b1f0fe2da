// libFuzzer target: the PC -> controller byte stream of the '@'-protocol as the simulated
// controller reads it: reassembly at '@', decoding, and the section-6 sequencer. Only ProtocolError
// may come out; a decoded command must encode and decode back to itself.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "cnc_bridge/at_protocol/codec.h"
#include "cnc_bridge/at_protocol/sequencer.h"
#include "cnc_bridge/common/error.h"

using namespace cnc_bridge::at_protocol;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  CommandReassembler reassembler;
  Sequencer sequencer;
  const auto result = reassembler.feed(data, size);
  for (const auto& message : result.messages)
  {
    try
    {
      const Command command = decodeCommand(message);
      const std::string wire = encode(command);
      if (encode(decodeCommand(wire.substr(0, wire.size() - 1))) != wire)
      {
        std::abort();
      }
      if (sequencer.refusal(command).empty())
      {
        sequencer.apply(command);
      }
      else
      {
        try
        {
          sequencer.apply(command);
          std::abort();  // a refused command must throw
        }
        catch (const cnc_bridge::ProtocolError&)
        {
        }
      }
    }
    catch (const cnc_bridge::ProtocolError&)
    {
    }
  }
  return 0;
}
