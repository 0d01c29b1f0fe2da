// Unit tests of the DPRNT core: the Haas formatter against the examples and rules of the Haas mill
// programming manual ("Formatted Output", DPRNT[] examples), the tolerant parser against lines as
// controls print them, the line assembler against the byte-level faults of serial links, the YAML
// rules, and the inputs (a reopened stream, a followed file) without any ROS.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <fstream>
#include <mutex>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dprnt/format.h"
#include "cnc_bridge/dprnt/input.h"
#include "cnc_bridge/dprnt/line_assembler.h"
#include "cnc_bridge/dprnt/parser.h"
#include "cnc_bridge/dprnt/rules.h"
#include "testing/fake_transport.h"

using namespace cnc_bridge;
using namespace cnc_bridge::dprnt;

namespace
{
// Macro variables of the manual's example: #1 = 1.5436, #2 = 123.456789.
double manualVariables(int n)
{
  switch (n)
  {
    case 1:
      return 1.5436;
    case 2:
      return 123.456789;
    case 5223:
      return -0.0125;
    default:
      return 0.0;
  }
}

std::vector<std::string> assemble(LineAssembler& assembler, const std::string& bytes,
                                  std::vector<std::string>* overlong = nullptr)
{
  std::vector<std::string> lines;
  assembler.feed(bytes,
                 [&](const LineEvent& event)
                 {
                   if (event.kind == LineEvent::Kind::kLine)
                     lines.emplace_back(event.text);
                   else if (overlong)
                     overlong->emplace_back(event.text);
                 });
  return lines;
}
}  // namespace

// ---------------------------------------------------------------------------------------------
// Formatter: expected strings written by hand from the manual's rules.

TEST(DprntFormat, ManualExampleEachFormat)
{
  // N1 #1= 1.5436; N2 DPRNT[X#1[44]*Z#1[03]*T#1[40]];
  EXPECT_EQ(formatValue(1.5436, 4, 4), "   1.5436");  // 3 leading spaces fill 4 whole places
  EXPECT_EQ(formatValue(1.5436, 0, 3), "1.544");      // a whole digit is printed even for w = 0; rounded
  EXPECT_EQ(formatValue(1.5436, 4, 0), "   1");       // f = 0: no decimal point, fraction dropped (manual: T 1)
}

TEST(DprntFormat, ManualExampleStatement)
{
  EXPECT_EQ(formatStatement("X#1[44]*Z#1[03]*T#1[04]", manualVariables), "X   1.5436 Z1.544 T1.5436");
  EXPECT_EQ(formatStatement("X#1[44]*Z#1[03]*T#1[40]", manualVariables), "X   1.5436 Z1.544 T   1");
  // N3 DPRNT[***MEASURED*INSIDE*DIAMETER***]; asterisks print as spaces.
  EXPECT_EQ(formatStatement("***MEASURED*INSIDE*DIAMETER***", manualVariables), "   MEASURED INSIDE DIAMETER   ");
  // N4 DPRNT[]; only the line end.
  EXPECT_EQ(formatStatement("", manualVariables), "");
  // OpenDNC's grid probe line (docs/protocols/dprnt.md#surface-model): DPRNT[#5223[44]];
  EXPECT_EQ(formatStatement("#5223[44]", manualVariables), "  -0.0125");
  EXPECT_EQ(formatStatement("Z*OFFSET*IS*#5223[44]", manualVariables), "Z OFFSET IS   -0.0125");
}

TEST(DprntFormat, WholePartWiderThanReservedExpandsTheField)
{
  EXPECT_EQ(formatValue(123.456789, 3, 5), "123.45679");
  EXPECT_EQ(formatValue(123.456789, 1, 5), "123.45679");
  EXPECT_EQ(formatValue(123.456789, 8, 0), "     123");
  EXPECT_EQ(formatValue(123.456789, 0, 1), "123.5");
}

TEST(DprntFormat, RoundsTheDecimalValueHalfAwayFromZero)
{
  EXPECT_EQ(formatValue(0.0125, 1, 3), "0.013");  // binary 0.01249999... must still round up
  EXPECT_EQ(formatValue(-0.0125, 1, 3), "-0.013");
  EXPECT_EQ(formatValue(1.99999, 1, 2), "2.00");
  EXPECT_EQ(formatValue(9.9996, 1, 3), "10.000");
  EXPECT_EQ(formatValue(0.5, 1, 0), "0");
  EXPECT_EQ(formatValue(-1.7, 1, 0), "-1");
  EXPECT_EQ(formatValue(-0.4, 1, 0), "0");
  EXPECT_EQ(formatValue(2.0, 2, 4), " 2.0000");  // trailing zeros are printed
}

TEST(DprntFormat, NegativeValuesAndNegativeZero)
{
  EXPECT_EQ(formatValue(-1.2345, 4, 4), "  -1.2345");
  EXPECT_EQ(formatValue(-0.0004, 1, 3), "0.000");  // rounds to zero: no "-0.000"
  EXPECT_EQ(formatValue(-12.0, 1, 0), "-12");
}

TEST(DprntFormat, IllegalFormatsAreRejected)
{
  // The manual's illegal examples: [00] [54] [45] [36].
  EXPECT_THROW(formatValue(1.0, 0, 0), ConfigError);
  EXPECT_THROW(formatValue(1.0, 5, 4), ConfigError);
  EXPECT_THROW(formatValue(1.0, 4, 5), ConfigError);
  EXPECT_THROW(formatValue(1.0, 3, 6), ConfigError);
  EXPECT_NO_THROW(formatValue(1.0, 4, 4));
  EXPECT_THROW(formatStatement("X#1[4]", manualVariables), ProtocolError);
  EXPECT_THROW(formatStatement("X#[44]", manualVariables), ProtocolError);
  EXPECT_THROW(formatStatement("X#1", manualVariables), ProtocolError);
}

// ---------------------------------------------------------------------------------------------
// Parser.

TEST(DprntParser, ManualExampleAsPrintedAndAsFormatted)
{
  for (const std::string line : {"X1.5436 Z 1.544 T 1", "X   1.5436 Z1.544 T   1", "X1.5436Z1.544T1"})
  {
    const auto v = LineParser::parse(line);
    ASSERT_EQ(v.size(), 3u) << line;
    EXPECT_EQ(v[0].label, "X");
    EXPECT_DOUBLE_EQ(v[0].value, 1.5436);
    EXPECT_EQ(v[1].label, "Z");
    EXPECT_DOUBLE_EQ(v[1].value, 1.544);
    EXPECT_EQ(v[2].label, "T");
    EXPECT_DOUBLE_EQ(v[2].value, 1.0);
  }
}

TEST(DprntParser, WordsBeforeAValueFormTheLabel)
{
  auto v = LineParser::parse("Z OFFSET IS -1.2345");
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].label, "Z OFFSET");
  EXPECT_DOUBLE_EQ(v[0].value, -1.2345);

  v = LineParser::parse("   MEASURED  INSIDE DIAMETER =  2.0010");
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].label, "MEASURED INSIDE DIAMETER");
  EXPECT_DOUBLE_EQ(v[0].value, 2.001);

  v = LineParser::parse("PROBE X 1.5 RESULT #5223 -0.01");
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].label, "X");
  EXPECT_EQ(v[1].label, "#5223");

  v = LineParser::parse("PARTS: 4523 CYCLE 12.5");
  ASSERT_EQ(v.size(), 2u);
  EXPECT_EQ(v[0].label, "PARTS");
  EXPECT_EQ(v[1].label, "CYCLE");
  EXPECT_DOUBLE_EQ(v[1].value, 12.5);
}

TEST(DprntParser, VariableNamesAreLabels)
{
  const auto v = LineParser::parse("#5223 -0.0125");
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].label, "#5223");
  EXPECT_DOUBLE_EQ(v[0].value, -0.0125);
}

TEST(DprntParser, BareNumbersHaveEmptyLabels)
{
  auto v = LineParser::parse("  -0.0125");
  ASSERT_EQ(v.size(), 1u);
  EXPECT_EQ(v[0].label, "");
  EXPECT_DOUBLE_EQ(v[0].value, -0.0125);
  v = LineParser::parse("1.5 .25 7.");
  ASSERT_EQ(v.size(), 3u);
  EXPECT_DOUBLE_EQ(v[1].value, 0.25);
  EXPECT_DOUBLE_EQ(v[2].value, 7.0);
}

TEST(DprntParser, SignsSeparatedBySpacesAndGluedWords)
{
  auto v = LineParser::parse("X - 1.5 Y+2 O00110 G54");
  ASSERT_EQ(v.size(), 4u);
  EXPECT_DOUBLE_EQ(v[0].value, -1.5);
  EXPECT_DOUBLE_EQ(v[1].value, 2.0);
  EXPECT_EQ(v[2].label, "O");
  EXPECT_DOUBLE_EQ(v[2].value, 110.0);
  EXPECT_EQ(v[3].label, "G");
}

TEST(DprntParser, LinesWithoutNumbersAndReusedStorage)
{
  std::vector<LabeledValue> out = LineParser::parse("A1 B2 C3");
  EXPECT_EQ(LineParser::parse("MEASURED INSIDE DIAMETER", out), 0u);
  EXPECT_TRUE(out.empty());
  EXPECT_EQ(LineParser::parse("", out), 0u);
  EXPECT_EQ(LineParser::parse("- . -. #", out), 0u);
  EXPECT_EQ(LineParser::parse("X1", out), 1u);
  EXPECT_NE(findLabel(out, "X"), nullptr);
  EXPECT_EQ(findLabel(out, "Y"), nullptr);
}

// ---------------------------------------------------------------------------------------------
// Line assembler.

TEST(DprntAssembler, AllLineEndsAndSplitCrLf)
{
  LineAssembler a;
  EXPECT_EQ(assemble(a, "A1\rB2\nC3\r\nD4\r"), (std::vector<std::string>{"A1", "B2", "C3", "D4"}));
  // CR at the end of one read, LF at the start of the next: still one line end.
  EXPECT_EQ(assemble(a, "E5\n"), std::vector<std::string>{"E5"});
  EXPECT_EQ(assemble(a, "F6\r"), std::vector<std::string>{"F6"});
  EXPECT_EQ(assemble(a, "\nG7\r"), std::vector<std::string>{"G7"});
  EXPECT_EQ(a.stats().empty_lines, 0u);
  EXPECT_EQ(assemble(a, "\r\r"), std::vector<std::string>{});  // DPRNT[] twice
  EXPECT_EQ(a.stats().empty_lines, 2u);
  EXPECT_EQ(a.stats().lines, 7u);
}

TEST(DprntAssembler, EmptyLinesOnRequest)
{
  LineAssembler a(256, true, true);
  EXPECT_EQ(assemble(a, "\rX1\r\n\r"), (std::vector<std::string>{"", "X1", ""}));
}

TEST(DprntAssembler, LeadersAndControlCodesAreDropped)
{
  LineAssembler a;
  // Fanuc POPEN: DC2 then NUL leader; PCLOS: DC4; tape feed DEL; ^Z padding.
  const std::string bytes = std::string("\x12\0\0\0X1.0\r\x14\x7f\x1a", 12);
  EXPECT_EQ(assemble(a, bytes), std::vector<std::string>{"X1.0"});
  EXPECT_EQ(a.stats().control_bytes, 7u);
  EXPECT_EQ(a.stats().garbage_bytes, 0u);
}

TEST(DprntAssembler, ParityBitIsMasked)
{
  // "Z1.5\r" with even parity in bit 7 (7E1 read as 8N1): Z=0x5A (4 ones: 0x5A), '1'=0x31 (3: 0xB1),
  // '.'=0x2E (4: 0x2E), '5'=0x35 (4: 0x35), CR=0x0D (3: 0x8D).
  const std::string bytes = "\x5A\xB1\x2E\x35\x8D";
  LineAssembler masked;
  EXPECT_EQ(assemble(masked, bytes), std::vector<std::string>{"Z1.5"});
  LineAssembler raw(256, false);
  EXPECT_EQ(assemble(raw, bytes), std::vector<std::string>{});  // 0x8D is not a line end unmasked
  EXPECT_EQ(raw.stats().garbage_bytes, 2u);
}

TEST(DprntAssembler, GarbageIsCountedAndTheLineKept)
{
  LineAssembler a;
  EXPECT_EQ(assemble(a,
                     "X\x01\x02"
                     "1.\x1b"
                     "5\tY2\r"),
            std::vector<std::string>{"X1.5 Y2"});
  EXPECT_EQ(a.stats().garbage_bytes, 3u);
}

TEST(DprntAssembler, OverlongLinesAreReportedSkippedAndTheStreamRecovers)
{
  LineAssembler a(8);
  std::vector<std::string> overlong;
  const auto lines = assemble(a, "12345678\r123456789ABCDEF\rX1\r", &overlong);
  EXPECT_EQ(lines, (std::vector<std::string>{"12345678", "X1"}));
  ASSERT_EQ(overlong.size(), 1u);
  EXPECT_EQ(overlong[0], "12345678");
  EXPECT_EQ(a.stats().overlong, 1u);
  // Over-long across several reads: reported once, recovery at the line end.
  EXPECT_EQ(assemble(a, std::string(20, 'A'), &overlong), std::vector<std::string>{});
  EXPECT_EQ(assemble(a, std::string(20, 'B'), &overlong), std::vector<std::string>{});
  EXPECT_EQ(assemble(a, "\nY2\n", &overlong), std::vector<std::string>{"Y2"});
  EXPECT_EQ(a.stats().overlong, 2u);
}

TEST(DprntAssembler, ResetDropsAndCountsThePartialLine)
{
  LineAssembler a;
  EXPECT_EQ(assemble(a, "X1.0 Y"), std::vector<std::string>{});
  EXPECT_EQ(a.pending(), 6u);
  a.reset();
  EXPECT_EQ(a.stats().partial_dropped, 1u);
  EXPECT_EQ(assemble(a, "Z2\r"), std::vector<std::string>{"Z2"});
  a.reset();
  EXPECT_EQ(a.stats().partial_dropped, 1u);  // nothing pending: nothing lost
}

// ---------------------------------------------------------------------------------------------
// Rules.

namespace
{
const char* kRules = R"(
rules:
  - name: probe_hit
    type: point
    labels: [X, Y, Z]
    regex: '^PROBE'
    frame: work
  - name: z_offset
    type: float64
    regex: 'Z OFFSET IS\s*(-?\s*[0-9.]+)'
    value: $1
    units: inch
  - name: grid_z
    type: float64
    labels: ['#5223']
    value: '#5223'
    units: mm
  - name: cycle_end
    type: cycle_event
    event: end
    regex: '^CYCLE END (\w+)'
    part_count: PARTS
    cycle_time: TIME
    program: $1
)";

std::vector<RuleOutput> run(const RuleSet& rules, const std::string& line)
{
  std::vector<RuleOutput> out;
  rules.evaluate(line, LineParser::parse(line), out);
  return out;
}
}  // namespace

TEST(DprntRules, PointInInchesBecomesMetres)
{
  const RuleSet rules = RuleSet::fromYaml(kRules, "inch");
  ASSERT_EQ(rules.rules().size(), 4u);
  EXPECT_EQ(rules.rules()[0].topic, "dprnt/probe_hit");
  const auto out = run(rules, "PROBE X   1.5000 Y   0.5000 Z  -0.0125");
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].rule, 0u);
  EXPECT_NEAR(out[0].x, 1.5 * 0.0254, 1e-12);
  EXPECT_NEAR(out[0].y, 0.5 * 0.0254, 1e-12);
  EXPECT_NEAR(out[0].z, -0.0125 * 0.0254, 1e-12);
  // Millimetre programs: the same line is 1000 times smaller in metres.
  const auto mm = run(RuleSet::fromYaml(kRules, "mm"), "PROBE X1.5 Y0.5 Z-0.0125");
  ASSERT_EQ(mm.size(), 1u);
  EXPECT_NEAR(mm[0].x, 0.0015, 1e-12);
  // Labels present but no PROBE word: no point.
  EXPECT_TRUE(run(rules, "X1 Y2 Z3").empty());
}

TEST(DprntRules, AMachinePositionRuleSaysWhichStatePositionItIs)
{
  const RuleSet rules = RuleSet::fromYaml(R"(
rules:
  - {name: reported, type: point, regex: '^MACHINE', frame: machine, state: position}
  - {name: commanded, type: point, regex: '^BLOCK END', frame: machine, state: commanded_position}
  - {name: probe, type: point, regex: '^PROBE'}
)",
                                          "mm");
  ASSERT_EQ(rules.rules().size(), 3u);
  EXPECT_EQ(rules.rules()[0].state, StateField::kPosition);
  EXPECT_EQ(rules.rules()[1].state, StateField::kCommandedPosition);
  EXPECT_EQ(rules.rules()[2].state, StateField::kNone);
  // The shipped rules: the MACHINE line of config/dprnt/grid_probe.nc is the reported position.
  const RuleSet shipped = RuleSet::fromFile(std::string(CONFIG_DIR) + "/dprnt_rules.yaml", "inch");
  const auto machine = std::find_if(shipped.rules().begin(), shipped.rules().end(),
                                    [](const Rule& r) { return r.name == "machine_position"; });
  ASSERT_NE(machine, shipped.rules().end());
  EXPECT_EQ(machine->state, StateField::kPosition);
}

TEST(DprntRules, RegexGroupsAndLabelSets)
{
  const RuleSet rules = RuleSet::fromYaml(kRules);
  auto out = run(rules, "Z OFFSET IS  -1.2345");
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].rule, 1u);
  EXPECT_NEAR(out[0].value, -1.2345 * 0.0254, 1e-12);
  out = run(rules, "#5223   -0.0125");
  ASSERT_EQ(out.size(), 1u);
  EXPECT_NEAR(out[0].value, -0.0125e-3, 1e-15);
}

TEST(DprntRules, CycleEventCarriesCountTimeAndProgram)
{
  const RuleSet rules = RuleSet::fromYaml(kRules);
  auto out = run(rules, "CYCLE END O00110 PARTS 12 TIME 93.5");
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(rules.rules()[out[0].rule].event, CycleEventKind::kEnd);
  EXPECT_EQ(out[0].part_count, 12);
  EXPECT_DOUBLE_EQ(out[0].cycle_time, 93.5);
  EXPECT_EQ(out[0].program, "O00110");
  // Missing optional values stay unknown.
  out = run(rules, "CYCLE END O1");
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].part_count, -1);
  EXPECT_LT(out[0].cycle_time, 0);
}

TEST(DprntRules, CountsOutsideTheCountableRangeStayUnknown)
{
  const RuleSet rules = RuleSet::fromYaml(kRules);
  // A garbled line can carry a number no counter holds; the event still goes out, without a count.
  for (const char* line : {"CYCLE END O1 PARTS 55555555555555555555555555555555555555", "CYCLE END O1 PARTS -3",
                           "CYCLE END O1 PARTS 2.5 TIME -4"})
  {
    const auto out = run(rules, line);
    ASSERT_EQ(out.size(), 1u) << line;
    EXPECT_EQ(out[0].part_count, -1) << line;
    EXPECT_LT(out[0].cycle_time, 0) << line;
  }
  const auto largest = run(rules, "CYCLE END O1 PARTS 9007199254740992");
  ASSERT_EQ(largest.size(), 1u);
  EXPECT_EQ(largest[0].part_count, 9007199254740992LL);
}

TEST(DprntRules, InvalidRulesAreRejectedWithTheirName)
{
  const auto message = [](const std::string& yaml)
  {
    try
    {
      RuleSet::fromYaml(yaml);
    }
    catch (const ConfigError& e)
    {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("rules: [{name: a, type: vector, labels: [X]}]").find("(a): \"type\""), std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: float64, regex: '(['}]").find("bad regex"), std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: float64, labels: [X]}, {name: a, type: float64, labels: [X]}]")
                .find("duplicate"),
            std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: float64}]").find("regex"), std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: float64, regex: 'X(1)', value: $2}]").find("$2"), std::string::npos);
  EXPECT_NE(message("rules: [{name: 'a b', type: float64, labels: [X]}]").find("name"), std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: point, labels: [X], units: furlong}]").find("furlong"), std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: cycle_event, labels: [X], event: lunch}]").find("lunch"),
            std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: float64, labels: [X], topic: /abs}]").find("relative"), std::string::npos);
  EXPECT_NE(message("rules: {{{").find("YAML"), std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: point, labels: [X], state: position}]").find("needs \"frame: machine\""),
            std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: point, labels: [X], frame: machine, state: spindle}]")
                .find("position or commanded_position"),
            std::string::npos);
  EXPECT_NE(message("rules: [{name: a, type: float64, labels: [X], state: position}]").find("point rules"),
            std::string::npos);
  EXPECT_THROW(RuleSet::fromFile("/nonexistent/rules.yaml"), ConfigError);
  EXPECT_TRUE(RuleSet::fromYaml("rules:").rules().empty());
}

// ---------------------------------------------------------------------------------------------
// Inputs.

namespace
{
// Collects bytes and link states from an input thread; tests wait on it, never sleep.
struct Sink
{
  std::mutex mutex;
  std::condition_variable cv;
  std::string bytes;
  std::vector<LinkState> states;
  std::vector<std::string> messages;

  DprntInput::BytesHandler bytesHandler()
  {
    return [this](const uint8_t* data, size_t size)
    {
      std::lock_guard<std::mutex> lock(mutex);
      bytes.append(reinterpret_cast<const char*>(data), size);
      cv.notify_all();
    };
  }
  /// Marks a start-over in the byte record as '|', where the reader would drop its partial line.
  DprntInput::RestartHandler restartHandler()
  {
    return [this](const std::string& why)
    {
      std::lock_guard<std::mutex> lock(mutex);
      bytes.push_back('|');
      messages.push_back(why);
      cv.notify_all();
    };
  }
  DprntInput::StateHandler stateHandler()
  {
    return [this](LinkState state, const std::string& why)
    {
      std::lock_guard<std::mutex> lock(mutex);
      states.push_back(state);
      messages.push_back(why);
      cv.notify_all();
    };
  }
  bool waitForBytes(const std::string& expected)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return cv.wait_for(lock, std::chrono::seconds(5), [&] { return bytes == expected; });
  }
  bool waitForMessage(const std::string& part)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return cv.wait_for(lock, std::chrono::seconds(5),
                       [&]
                       {
                         return std::any_of(messages.begin(), messages.end(),
                                            [&](const std::string& m) { return m.find(part) != std::string::npos; });
                       });
  }
  bool waitForUps(size_t count)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return cv.wait_for(
        lock, std::chrono::seconds(5),
        [&] { return static_cast<size_t>(std::count(states.begin(), states.end(), LinkState::kUp)) >= count; });
  }
};
}  // namespace

TEST(DprntInput, StreamReconnectsAfterThePeerVanishes)
{
  std::mutex mutex;
  std::vector<FakeTransport*> links;
  int opens = 0;
  StreamInput input(
      [&]() -> std::unique_ptr<Transport>
      {
        std::lock_guard<std::mutex> lock(mutex);
        auto link = std::make_unique<FakeTransport>("fake machine");
        link->feed(opens++ == 0 ? "X1\r" : "Y2\r");
        if (opens == 1)
          link->disconnect();  // the peer goes away after its first line
        links.push_back(link.get());
        return link;
      },
      "fake machine", Backoff(Milliseconds(1), Milliseconds(5)));
  Sink sink;
  input.start(sink.bytesHandler(), sink.stateHandler());
  EXPECT_TRUE(sink.waitForBytes("X1\rY2\r"));
  EXPECT_TRUE(sink.waitForUps(2));
  EXPECT_GE(input.reconnects(), 1u);
  input.stop();
  EXPECT_EQ(sink.states.back(), LinkState::kDown);
}

TEST(DprntInput, FileIsFollowedThroughTruncationAndRotation)
{
  char dir_template[] = "/tmp/test_dprnt_file_XXXXXX";
  ASSERT_NE(mkdtemp(dir_template), nullptr);
  const std::string dir = dir_template;
  const std::string path = dir + "/dprnt.txt";
  {
    std::ofstream(path) << "OLD 1\r";  // history before we start: skipped (from_start false)
  }
  FileInput input(path, false, Milliseconds(2), Backoff(Milliseconds(1), Milliseconds(5)));
  Sink sink;
  input.start(sink.bytesHandler(), sink.stateHandler());
  ASSERT_TRUE(sink.waitForUps(1));
  {
    std::ofstream(path, std::ios::app) << "X1\r";
  }
  ASSERT_TRUE(sink.waitForBytes("X1\r"));
  // Truncated by the control (a new program run starts the file again), then shorter content.
  {
    std::ofstream(path, std::ios::trunc) << "";
  }
  // Wait until the follower noticed the truncation before writing again, else it cannot tell.
  ASSERT_TRUE(sink.waitForMessage("truncated"));
  EXPECT_EQ(input.restarts(), 1u);
  {
    std::ofstream(path, std::ios::app) << "T2\r";
  }
  ASSERT_TRUE(sink.waitForBytes("X1\rT2\r"));
  // Rotation: the file is renamed away after one more line, a new file takes its name.
  {
    std::ofstream(path, std::ios::app) << "LAST 3\r";
  }
  ASSERT_EQ(std::rename(path.c_str(), (path + ".1").c_str()), 0);
  {
    std::ofstream(path) << "NEW 4\r";
  }
  EXPECT_TRUE(sink.waitForBytes("X1\rT2\rLAST 3\rNEW 4\r"));
  input.stop();
  std::remove((path + ".1").c_str());
  std::remove(path.c_str());
  rmdir(dir.c_str());
}

namespace
{
// A temporary directory with one DPRNT file in it, removed at the end.
struct TempFile
{
  std::string dir, path;
  TempFile()
  {
    char dir_template[] = "/tmp/test_dprnt_file_XXXXXX";
    EXPECT_NE(mkdtemp(dir_template), nullptr);
    dir = dir_template;
    path = dir + "/dprnt.txt";
    std::ofstream(path) << "";
  }
  ~TempFile()
  {
    std::remove((path + ".1").c_str());
    std::remove(path.c_str());
    rmdir(dir.c_str());
  }
  void append(const std::string& text) const { std::ofstream(path, std::ios::app) << text; }
  void rewrite(const std::string& text) const { std::ofstream(path, std::ios::trunc) << text; }
};

// Feeds a byte record of Sink (with '|' for a start-over) to an assembler as dprnt_node does:
// a start-over resets it. Returns the lines.
std::vector<std::string> linesOf(const std::string& record, LineAssembler& assembler)
{
  std::vector<std::string> lines;
  for (char c : record)
  {
    if (c == '|')
      assembler.reset();
    else
      assembler.feed(std::string_view(&c, 1), [&](const LineEvent& e) { lines.emplace_back(e.text); });
  }
  return lines;
}
}  // namespace

TEST(DprntInput, PartialLineBeforeTruncationIsNotGluedToTheNewContent)
{
  TempFile file;
  FileInput input(file.path, false, Milliseconds(2), Backoff(Milliseconds(1), Milliseconds(5)));
  Sink sink;
  input.start(sink.bytesHandler(), sink.stateHandler(), sink.restartHandler());
  ASSERT_TRUE(sink.waitForUps(1));
  file.append("PROBE X 1.0 Y");  // the control was cut off mid-line, then starts the file again
  ASSERT_TRUE(sink.waitForBytes("PROBE X 1.0 Y"));
  file.rewrite("");
  ASSERT_TRUE(sink.waitForMessage("truncated"));
  file.append(" 2.0 Z 3.0\r");
  ASSERT_TRUE(sink.waitForBytes("PROBE X 1.0 Y| 2.0 Z 3.0\r"));
  input.stop();
  LineAssembler assembler;
  EXPECT_EQ(linesOf(sink.bytes, assembler), std::vector<std::string>{" 2.0 Z 3.0"});
  EXPECT_EQ(assembler.stats().partial_dropped, 1u);
}

TEST(DprntInput, PartialLineBeforeRotationIsNotGluedToTheNewFile)
{
  TempFile file;
  FileInput input(file.path, false, Milliseconds(2), Backoff(Milliseconds(1), Milliseconds(5)));
  Sink sink;
  input.start(sink.bytesHandler(), sink.stateHandler(), sink.restartHandler());
  ASSERT_TRUE(sink.waitForUps(1));
  file.append("OLD 1\rCUT OFF");
  ASSERT_TRUE(sink.waitForBytes("OLD 1\rCUT OFF"));
  ASSERT_EQ(std::rename(file.path.c_str(), (file.path + ".1").c_str()), 0);
  file.append("NEW 2\r");
  ASSERT_TRUE(sink.waitForBytes("OLD 1\rCUT OFF|NEW 2\r"));
  EXPECT_TRUE(sink.waitForMessage("rotated"));
  input.stop();
  LineAssembler assembler;
  EXPECT_EQ(linesOf(sink.bytes, assembler), (std::vector<std::string>{"OLD 1", "NEW 2"}));
  EXPECT_EQ(assembler.stats().partial_dropped, 1u);
}

TEST(DprntInput, TruncatedAndRegrownBetweenTwoReadsIsReadFromItsStart)
{
  TempFile file;
  // The bytes handler holds the reader on its first chunk while the control truncates the file
  // and writes more than it held: by size alone that looks like an append.
  std::mutex mutex;
  std::condition_variable cv;
  bool holding = false, release = false;
  Sink sink;
  const auto record = sink.bytesHandler();
  FileInput input(file.path, false, Milliseconds(2), Backoff(Milliseconds(1), Milliseconds(5)));
  input.start(
      [&](const uint8_t* data, size_t size)
      {
        record(data, size);
        std::unique_lock<std::mutex> lock(mutex);
        if (!release)
        {
          holding = true;
          cv.notify_all();
          cv.wait(lock, [&] { return release; });
        }
      },
      sink.stateHandler(), sink.restartHandler());
  ASSERT_TRUE(sink.waitForUps(1));
  file.append("A 1\r");
  {
    std::unique_lock<std::mutex> lock(mutex);
    ASSERT_TRUE(cv.wait_for(lock, std::chrono::seconds(5), [&] { return holding; }));
  }
  file.rewrite("CYCLE START O1\rB 2\r");
  {
    std::lock_guard<std::mutex> lock(mutex);
    release = true;
    cv.notify_all();
  }
  EXPECT_TRUE(sink.waitForBytes("A 1\r|CYCLE START O1\rB 2\r"));
  EXPECT_TRUE(sink.waitForMessage("rewritten"));
  EXPECT_EQ(input.restarts(), 1u);
  input.stop();
}

TEST(DprntInput, AppendsAreNotTakenForRewrites)
{
  TempFile file;
  file.append("HISTORY 0\r");  // skipped (from_start false), yet compared against
  FileInput input(file.path, false, Milliseconds(2), Backoff(Milliseconds(1), Milliseconds(5)));
  Sink sink;
  input.start(sink.bytesHandler(), sink.stateHandler(), sink.restartHandler());
  ASSERT_TRUE(sink.waitForUps(1));
  std::string expected;
  for (int i = 1; i <= 20; ++i)
  {
    const std::string line = "LINE " + std::to_string(i) + "\r";
    file.append(line);
    expected += line;
    ASSERT_TRUE(sink.waitForBytes(expected));
  }
  EXPECT_EQ(input.restarts(), 0u);
  input.stop();
}

TEST(DprntInput, MissingFileIsWaitedFor)
{
  const std::string path = "/tmp/test_dprnt_missing_" + std::to_string(getpid()) + ".txt";
  std::remove(path.c_str());
  // from_start false: a file created after start holds only new output and is read from its start.
  FileInput input(path, false, Milliseconds(2), Backoff(Milliseconds(1), Milliseconds(5)));
  Sink sink;
  input.start(sink.bytesHandler(), sink.stateHandler());
  {
    std::unique_lock<std::mutex> lock(sink.mutex);
    ASSERT_TRUE(sink.cv.wait_for(lock, std::chrono::seconds(5),
                                 [&]
                                 { return std::count(sink.states.begin(), sink.states.end(), LinkState::kDown) > 0; }));
  }
  {
    std::ofstream(path) << "Z1\r";
  }
  EXPECT_TRUE(sink.waitForBytes("Z1\r"));
  input.stop();
  std::remove(path.c_str());
}
