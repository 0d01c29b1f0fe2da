// libFuzzer target: the controller -> PC report stream of the '@'-protocol. Arbitrary bytes go
// through the line reassembler (in two pieces, to exercise split reads) and every line through
// parseReport: only ProtocolError may come out, and whatever parses must encode and parse back to
// the same report.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "cnc_bridge/at_protocol/codec.h"
#include "cnc_bridge/common/error.h"

using namespace cnc_bridge::at_protocol;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  LineReassembler lines;
  const size_t cut = size > 0 ? data[0] % (size + 1) : 0;
  auto first = lines.feed(data, cut);
  auto second = lines.feed(data + cut, size - cut);
  first.messages.insert(first.messages.end(), second.messages.begin(), second.messages.end());
  for (const auto& line : first.messages)
  {
    if (line.size() > kMaxMessageLength)
    {
      std::abort();  // the reassembler must never hand out an overlong line
    }
    try
    {
      const Report report = parseReport(line);
      const std::string wire = encode(report);
      const Report again = parseReport(wire.substr(0, wire.size() - 1));
      if (again.index() != report.index() || encode(again) != wire)
      {
        std::abort();
      }
    }
    catch (const cnc_bridge::ProtocolError&)
    {
    }
  }
  return 0;
}
