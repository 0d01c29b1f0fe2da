// libFuzzer target: the MDC reply parser and everything that reads a parsed reply (matching,
// decoding, the monitor's cycle logic, the raw-query filter) on arbitrary bytes. Nothing may crash;
// malformed values may only throw ProtocolError.
#include <cstddef>
#include <cstdint>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mdc/mdc_monitor.h"
#include "cnc_bridge/mdc/mdc_protocol.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  using namespace cnc_bridge::mdc;
  static MdcMonitor monitor;  // state carried across inputs, as in a long session
  const std::string input(reinterpret_cast<const char*>(data), size);
  parseReadOnlyQuery(input);
  size_t start = 0;
  while (start <= input.size())
  {
    size_t end = input.find_first_of("\r\n", start);
    if (end == std::string::npos)
      end = input.size();
    const auto reply = parseReply(input.substr(start, end - start));
    start = end + 1;
    if (!reply)
      continue;
    answers(q(500), *reply);
    answers(macroQuery(5021), *reply);
    answers(q(105), *reply);
    try
    {
      toProgramStatus(*reply);
    }
    catch (const cnc_bridge::ProtocolError&)
    {
    }
    try
    {
      macroOf(*reply);
    }
    catch (const cnc_bridge::ProtocolError&)
    {
    }
    try
    {
      parseDuration(valueOf(*reply));
    }
    catch (const cnc_bridge::ProtocolError&)
    {
    }
    monitor.apply(*reply, Clock::time_point(std::chrono::milliseconds(static_cast<int64_t>(start))));
  }
  return 0;
}
