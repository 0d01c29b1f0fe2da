// libFuzzer target: arbitrary bytes through the DPRNT line assembler, the label/value parser and a
// rule set (regex and label rules), as bytes from a noisy serial line would go through dprnt_node.
// Checks invariants: lines stay within the limit and hold printable ASCII only.
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "cnc_bridge/dprnt/line_assembler.h"
#include "cnc_bridge/dprnt/parser.h"
#include "cnc_bridge/dprnt/rules.h"

namespace
{
const cnc_bridge::dprnt::RuleSet& rules()
{
  static const auto set = cnc_bridge::dprnt::RuleSet::fromYaml(R"(
rules:
  - {name: probe, type: point, regex: '^PROBE', labels: [X, Y, Z]}
  - {name: offset, type: float64, regex: 'IS\s*(-?\s*[0-9.]+)', value: $1, units: inch}
  - {name: end, type: cycle_event, event: end, regex: '^CYCLE END\s*(O\d+)?', program: $1, part_count: PARTS}
)");
  return set;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  using namespace cnc_bridge::dprnt;
  constexpr size_t kMax = 64;
  LineAssembler assembler(kMax, size > 0 && (data[0] & 1));
  std::vector<LabeledValue> values;
  std::vector<RuleOutput> outputs;
  assembler.feed(data, size,
                 [&](const LineEvent& event)
                 {
                   if (event.text.size() > kMax)
                     std::abort();
                   for (char c : event.text)
                   {
                     if (c < 0x20 || c > 0x7E)
                       std::abort();
                   }
                   LineParser::parse(event.text, values);
                   rules().evaluate(event.text, values, outputs);
                 });
  // The parser also takes any text directly (the node parses lines only, but stay safe).
  LineParser::parse(std::string_view(reinterpret_cast<const char*>(data), size), values);
  return 0;
}
