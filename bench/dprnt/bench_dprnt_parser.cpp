// Parser throughput of the DPRNT core on one core: lines per second through the line assembler
// plus the label/value parser (what dprnt_node does per line before publishing), and the parser
// alone, on a mix of lines as the grid probing program prints them. Prints one result per line.
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "cnc_bridge/dprnt/line_assembler.h"
#include "cnc_bridge/dprnt/parser.h"
#include "cnc_bridge/dprnt/rules.h"

int main(int argc, char** argv)
{
  using namespace cnc_bridge::dprnt;
  const size_t lines = argc > 1 ? std::stoul(argv[1]) : 2000000;
  const std::vector<std::string> mix = {"PROBE X   0.5000 Y   1.0000 Z  -0.0120",
                                        "X1.5436 Z 1.544 T 1",
                                        "Z OFFSET IS   -0.0125",
                                        "#5223   -0.0125",
                                        "  -0.0125",
                                        "CYCLE END O01000 PARTS      1"};
  std::string stream;
  for (size_t i = 0; i < 1000; ++i)
    stream += mix[i % mix.size()] + "\r";
  const size_t rounds = lines / 1000;

  std::vector<LabeledValue> values;
  size_t found = 0;
  auto start = std::chrono::steady_clock::now();
  LineAssembler assembler;
  for (size_t r = 0; r < rounds; ++r)
  {
    assembler.feed(stream, [&](const LineEvent& event) { found += LineParser::parse(event.text, values); });
  }
  double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("assemble+parse %.0f lines/s (%zu lines, %zu values)\n", rounds * 1000 / seconds, rounds * 1000, found);

  found = 0;
  start = std::chrono::steady_clock::now();
  for (size_t i = 0; i < rounds * 1000; ++i)
    found += LineParser::parse(mix[i % mix.size()], values);
  seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("parse %.0f lines/s (%zu values)\n", rounds * 1000 / seconds, found);

  // With the shipped rules (regular expressions dominate: the node's full per-line cost).
  const RuleSet rules = RuleSet::fromYaml(R"(
rules:
  - {name: probe_hit, type: point, regex: '^PROBE\b', labels: [X, Y, Z]}
  - {name: bare_z, type: float64, regex: '^\s*-?\d*\.\d+\s*$'}
  - {name: z_offset, type: float64, labels: ['Z OFFSET'], value: 'Z OFFSET'}
  - {name: cycle_end, type: cycle_event, event: end, regex: '^CYCLE END\s*(O\d+)?', program: $1, part_count: PARTS}
)");
  std::vector<RuleOutput> outputs;
  const size_t rule_lines = rounds * 100;
  start = std::chrono::steady_clock::now();
  for (size_t i = 0; i < rule_lines; ++i)
  {
    const std::string& line = mix[i % mix.size()];
    LineParser::parse(line, values);
    found += rules.evaluate(line, values, outputs);
  }
  seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("parse+rules %.0f lines/s\n", rule_lines / seconds);
  return 0;
}
