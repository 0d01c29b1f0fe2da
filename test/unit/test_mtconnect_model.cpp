// The machine model on the reference agent's recorded answers: the standard mapping, units to SI,
// cycle events from Execution, conditions with their codes, a mapping overridden by the user.
#include <gtest/gtest.h>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mtconnect/machine_model.h"
#include "mtconnect_fixtures.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mtconnect;
using cnc_bridge::mtconnect::testing::fixture;
using cnc_bridge::mtconnect::testing::parseResponse;

namespace
{
Document recorded(const std::string& name)
{
  return parseDocument(parseResponse(fixture(name + ".http")).body);
}

/// The stream's observations after \p from, in sequence order, as the follower delivers them.
std::vector<Observation> streamed(uint64_t from)
{
  std::vector<Observation> out;
  for (const auto& part : parseResponse(fixture("stream.http"), 0, false).parts)
  {
    for (const auto& o : parseDocument(part).observations)
    {
      if (o.sequence >= from)
        out.push_back(o);
    }
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const Observation& a, const Observation& b) { return a.sequence < b.sequence; });
  return out;
}

MachineModel modelOfProbe(Mapping mapping = defaultMapping())
{
  MachineModel model(std::move(mapping));
  model.setDevice(selectDevice(recorded("probe"), ""));
  return model;
}
}  // namespace

TEST(MtconnectModel, StandardMappingFindsEveryFieldOfTheMill)
{
  MachineModel model = modelOfProbe();
  EXPECT_TRUE(model.unmatched().empty());
  EXPECT_EQ(model.resolved().at("x_position"), "Xact");
  EXPECT_EQ(model.resolved().at("z_commanded"), "Zcom");
  EXPECT_EQ(model.resolved().at("spindle_speed"), "Sspeed");
  EXPECT_EQ(model.resolved().at("door"), "door_state");
}

TEST(MtconnectModel, CurrentGivesTheStateInSI)
{
  MachineModel model = modelOfProbe();
  const auto changes = model.apply(recorded("current").observations, true);
  EXPECT_TRUE(changes.state);
  EXPECT_TRUE(changes.events.empty());
  const MachineView& v = model.view();
  EXPECT_EQ(v.available, std::optional<bool>(true));
  EXPECT_EQ(v.estop, Tristate::kOff);
  EXPECT_EQ(v.mode, Mode::kAuto);
  EXPECT_EQ(v.execution, Execution::kReady);
  EXPECT_EQ(v.program, "O1234");
  EXPECT_EQ(v.part_count, 41);
  EXPECT_EQ(v.tool, 3);
  EXPECT_EQ(v.door, "CLOSED");
  ASSERT_TRUE(v.positionValid());
  // The adapter sent inches (1, 2, 3); the agent reports mm (25.4, ...); the model metres.
  EXPECT_NEAR(*v.position[0], 0.0254, 1e-9);
  EXPECT_NEAR(*v.position[1], 0.0508, 1e-9);
  EXPECT_NEAR(*v.position[2], 0.0762, 1e-9);
  EXPECT_TRUE(v.commandedValid());
  EXPECT_EQ(v.spindle_rpm, std::optional<double>(0.0));
}

TEST(MtconnectModel, StreamGivesCycleEventsAndConditions)
{
  MachineModel model = modelOfProbe();
  const Document current = recorded("current");
  model.apply(current.observations, true);
  const auto changes = model.apply(streamed(current.header.next_sequence), false);
  ASSERT_GE(changes.events.size(), 3u);
  EXPECT_EQ(changes.events[0].type, CycleEvent::kCycleStart);
  EXPECT_EQ(changes.events[1].type, CycleEvent::kCycleEnd);
  EXPECT_EQ(changes.events[2].type, CycleEvent::kCycleStart);
  // The cycle end came with the part counter's step: one event, no separate PART_COUNT.
  for (const auto& e : changes.events)
    EXPECT_NE(e.type, CycleEvent::kPartCount);
  EXPECT_GT(changes.events[1].cycle_time, 0.0);
  EXPECT_LT(changes.events[1].cycle_time, 10.0);
  EXPECT_EQ(changes.events[1].program, "O1234");
  // Conditions, in order: warning 1010, fault 2001, then both back to normal.
  std::vector<std::string> seen;
  for (const auto& c : changes.conditions)
    seen.push_back(std::to_string(static_cast<int>(c.level)) + ":" + c.native_code);
  ASSERT_GE(seen.size(), 4u);
  EXPECT_NE(std::find(seen.begin(), seen.end(), "2:1010"), seen.end());
  EXPECT_NE(std::find(seen.begin(), seen.end(), "3:2001"), seen.end());
  EXPECT_TRUE(model.activeConditions().empty());
  // The stream ends in a feed hold with the door open and the emergency stop pressed.
  EXPECT_EQ(model.view().execution, Execution::kPaused);
  EXPECT_EQ(model.view().execution_text, "INTERRUPTED");
  EXPECT_EQ(model.view().door, "OPEN");
  EXPECT_EQ(model.view().estop, Tristate::kOn);
  EXPECT_EQ(model.view().part_count, 42);
}

TEST(MtconnectModel, ActiveConditionsFollowNativeCodes)
{
  MachineModel model = modelOfProbe();
  auto condition = [](const std::string& level, const std::string& code, uint64_t seq)
  {
    Observation o;
    o.category = "CONDITION";
    o.element = level;
    o.data_item_id = "system";
    o.native_code = code;
    o.sequence = seq;
    o.value = level == "Normal" ? "" : "text " + code;
    return o;
  };
  model.apply({condition("Fault", "A", 1), condition("Warning", "B", 2)}, false);
  ASSERT_EQ(model.activeConditions().size(), 2u);
  model.apply({condition("Normal", "A", 3)}, false);
  ASSERT_EQ(model.activeConditions().size(), 1u);
  EXPECT_EQ(model.activeConditions()[0].native_code, "B");
  model.apply({condition("Normal", "", 4)}, false);
  EXPECT_TRUE(model.activeConditions().empty());
}

TEST(MtconnectModel, JoiningMidCycleStartsNoCycleButSeesItsEnd)
{
  MachineModel model = modelOfProbe();
  Observation active;
  active.data_item_id = "exec";
  active.category = "EVENT";
  active.value = "ACTIVE";
  active.timestamp = "2026-11-28T01:00:00Z";
  EXPECT_TRUE(model.apply({active}, true).events.empty());
  Observation ready = active;
  ready.value = "READY";
  ready.timestamp = "2026-11-28T01:00:30Z";
  const auto changes = model.apply({ready}, false);
  ASSERT_EQ(changes.events.size(), 1u);
  EXPECT_EQ(changes.events[0].type, CycleEvent::kCycleEnd);
  EXPECT_LT(changes.events[0].cycle_time, 0.0);  // its start was not seen
}

TEST(MtconnectModel, UnavailableMakesFieldsUnknown)
{
  MachineModel model = modelOfProbe();
  model.apply(recorded("current").observations, true);
  Observation x;
  x.data_item_id = "Xact";
  x.category = "SAMPLE";
  x.value = "UNAVAILABLE";
  Observation mode = x;
  mode.data_item_id = "mode";
  mode.category = "EVENT";
  model.apply({x, mode}, false);
  EXPECT_FALSE(model.view().positionValid());
  EXPECT_EQ(model.view().mode, Mode::kUnknown);
  model.forget();
  EXPECT_EQ(model.view().execution, Execution::kUnknown);
  EXPECT_EQ(model.view().part_count, -1);
}

TEST(MtconnectModel, MappingOverriddenBySelectors)
{
  // Another agent's style: positions by data item name, a program by its id.
  Mapping overrides{{"x_position", {"name=Xcom"}}, {"program", {"id=line"}}, {"door", {}}};
  MachineModel model = modelOfProbe(mergeMapping(overrides));
  EXPECT_EQ(model.resolved().at("x_position"), "Xcom");
  EXPECT_EQ(model.resolved().count("door"), 0u);
  EXPECT_EQ(model.resolved().at("y_position"), "Yact");  // the default stays for the rest
  try
  {
    mergeMapping({{"spindle", {"SPINDLE_SPEED"}}});
    FAIL() << "an unknown field accepted";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("spindle_speed"), std::string::npos) << e.what();
  }
  EXPECT_THROW(mergeMapping({{"tool", {"TOOL NUMBER"}}}), ConfigError);
  EXPECT_THROW(mergeMapping({{"tool", {"TOOL_NUMBER@"}}}), ConfigError);
}

TEST(MtconnectModel, PublicSampleHaasDeviceMapsItsAxes)
{
  MachineModel model;
  model.setDevice(selectDevice(parseDocument(fixture("samples/haas.xml")), ""));
  EXPECT_EQ(model.resolved().at("x_position"), "x1");  // not the Axes' POSITION condition
  EXPECT_EQ(model.resolved().at("spindle_speed"), "s1");
  EXPECT_EQ(model.resolved().at("part_count"), "PartCount");
}

TEST(MtconnectModel, UnitsToSI)
{
  EXPECT_DOUBLE_EQ(*siFactor("MILLIMETER"), 0.001);
  EXPECT_DOUBLE_EQ(*siFactor("INCH"), 0.0254);
  EXPECT_DOUBLE_EQ(*siFactor("INCH/MINUTE"), 0.0254 / 60);
  EXPECT_FALSE(siFactor("FURLONG").has_value());
  EXPECT_NEAR(*secondsBetween("2026-11-28T04:00:59.750Z", "2026-11-28T04:01:01.000000Z"), 1.25, 1e-9);
  EXPECT_FALSE(secondsBetween("yesterday", "2026-11-28T04:01:01Z").has_value());
}
