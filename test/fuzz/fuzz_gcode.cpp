// libFuzzer target: arbitrary bytes as a G-code program. Any input must end in moves or a
// ParseError, never a crash, a hang or unbounded memory; moves must be finite.
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <string>

#include "cnc_bridge/gcode/gcode.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  cnc_bridge::gcode::ParserOptions options;
  options.max_arc_segments = 2000;  // keep each input fast; the cap itself is under test
  cnc_bridge::gcode::Reader reader(in, options);
  try
  {
    cnc_bridge::gcode::Move move;
    while (reader.nextMove(move))
    {
      if (!std::isfinite(move.end.x) || !std::isfinite(move.end.y) || !std::isfinite(move.end.z))
      {
        std::abort();
      }
    }
  }
  catch (const cnc_bridge::gcode::ParseError&)
  {
  }
  return 0;
}
