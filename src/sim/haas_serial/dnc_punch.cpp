// The simulated control punching a program for backup: leader, DC2, the program with its EOB,
// DC4, trailer, optionally with the 7E1 parity bit set on every byte.
#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/dnc_codes.h"
#include "cnc_bridge/dnc/nc_program.h"
#include "dnc_sim.h"

namespace cnc_bridge
{
namespace sim
{
uint64_t punchProgram(Transport& link, const std::string& path, const PunchOptions& options, StopSignal& stop)
{
  dnc::CharacterRules anything;
  anything.reject_lowercase = false;
  anything.reject_inner_percent = false;
  const dnc::ProgramScan scan = dnc::scanProgram(path, anything, {}, options.eob.size());

  if (options.wait_for_dc1)
  {
    for (;;)
    {
      if (stop.stopped())
      {
        return 0;
      }
      const int c = link.readByte(Milliseconds(50));
      if (c >= 0 && dnc::maskParity(static_cast<uint8_t>(c)) == dnc::kDc1)
      {
        break;
      }
    }
  }
  uint64_t sent = 0;
  std::string out;
  const auto flush = [&]
  {
    if (options.seven_e1)
    {
      for (auto& c : out)
      {
        c = static_cast<char>(dnc::withEvenParity(static_cast<uint8_t>(c)));
      }
    }
    link.write(out);
    sent += out.size();
    out.clear();
    if (stop.stopped())
    {
      throw CancelledError("punch stopped");
    }
  };
  out.append(options.leader_length, '\0');
  if (options.dc_codes)
  {
    out.push_back(static_cast<char>(dnc::kDc2));
  }
  if (!scan.starts_with_percent)
  {
    out += "%" + options.eob;
  }
  dnc::LineReader reader(path);
  std::string line;
  while (reader.next(line))
  {
    const uint64_t n = reader.lineNumber();
    if (n < scan.first_text_line || n > scan.last_text_line)
    {
      continue;
    }
    if (n == scan.last_text_line && scan.ends_with_percent && !options.end_percent)
    {
      continue;
    }
    out += line + options.eob;
    if (out.size() >= 256)
    {
      flush();
    }
  }
  if (!scan.ends_with_percent && options.end_percent)
  {
    out += "%" + options.eob;
  }
  if (options.dc_codes)
  {
    out.push_back(static_cast<char>(dnc::kDc4));
  }
  out.append(options.leader_length, '\0');
  flush();
  link.drain();
  return sent;
}
}  // namespace sim
}  // namespace cnc_bridge
