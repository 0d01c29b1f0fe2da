// What haas_mdc_node makes of a Haas status (docs/haas_mdc_node.md): positions in metres in the
// control's unit or a fixed one, the e-stop from the Q500 status text, the variables of the poll
// plan, and the per-query period table.
#include <gtest/gtest.h>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mdc/mdc_readings.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mdc;

namespace
{
PollVariables haasDefaults()
{
  PollVariables vars;
  vars.position = {5021, 5022, 5023};
  vars.work = {5041, 5042, 5043};
  return vars;
}

MachineStatus statusAt(double x, double y, double z, Units units)
{
  MachineStatus status;
  status.variables = {{5021, x}, {5022, y}, {5023, z}};
  status.units = units;
  return status;
}
}  // namespace

TEST(MdcReadings, UnitSettingIsAutoInchOrMm)
{
  EXPECT_EQ(parseUnitSetting("auto", "~units"), UnitSetting::kAuto);
  EXPECT_EQ(parseUnitSetting("inch", "~units"), UnitSetting::kInch);
  EXPECT_EQ(parseUnitSetting("mm", "~units"), UnitSetting::kMillimetre);
  try
  {
    parseUnitSetting("metre", "/haas/units");
    FAIL() << "metre accepted";
  }
  catch (const ConfigError& e)
  {
    EXPECT_STREQ(e.what(), "/haas/units must be auto, inch or mm, not metre");
  }
}

TEST(MdcReadings, MetresPerUnitFollowsTheControlUnlessFixed)
{
  EXPECT_DOUBLE_EQ(metresPerUnit(UnitSetting::kAuto, Units::kInch), 0.0254);
  EXPECT_DOUBLE_EQ(metresPerUnit(UnitSetting::kAuto, Units::kMillimetre), 0.001);
  EXPECT_EQ(metresPerUnit(UnitSetting::kAuto, Units::kUnknown), 0.0);
  EXPECT_DOUBLE_EQ(metresPerUnit(UnitSetting::kMillimetre, Units::kInch), 0.001);
  EXPECT_DOUBLE_EQ(metresPerUnit(UnitSetting::kInch, Units::kUnknown), 0.0254);
}

TEST(MdcReadings, PositionInMetresOnlyWhenEveryAxisAndTheUnitAreKnown)
{
  const PollVariables vars = haasDefaults();
  const Readings inch = readingsFrom(statusAt(1.0, -2.0, 0.5, Units::kInch), vars);
  ASSERT_TRUE(inch.position_valid);
  EXPECT_DOUBLE_EQ(inch.position[0], 0.0254);
  EXPECT_DOUBLE_EQ(inch.position[1], -0.0508);
  EXPECT_DOUBLE_EQ(inch.position[2], 0.0127);
  EXPECT_FALSE(inch.work_offset_valid);

  EXPECT_FALSE(readingsFrom(statusAt(1.0, 2.0, 3.0, Units::kUnknown), vars).position_valid);
  MachineStatus missing_z = statusAt(1.0, 2.0, 3.0, Units::kMillimetre);
  missing_z.variables.erase(5023);
  EXPECT_FALSE(readingsFrom(missing_z, vars).position_valid);

  PollVariables no_positions = vars;
  no_positions.position.clear();
  EXPECT_FALSE(readingsFrom(statusAt(1.0, 2.0, 3.0, Units::kMillimetre), no_positions).position_valid);
}

TEST(MdcReadings, WorkOffsetComesWithThePositionInTheSameUnit)
{
  MachineStatus status = statusAt(100.0, 50.0, -10.0, Units::kMillimetre);
  status.work_offset[0] = 250.0;
  status.work_offset[1] = 125.0;
  EXPECT_FALSE(readingsFrom(status, haasDefaults()).work_offset_valid);  // Z not known yet
  status.work_offset[2] = -400.0;
  const Readings readings = readingsFrom(status, haasDefaults());
  ASSERT_TRUE(readings.work_offset_valid);
  EXPECT_DOUBLE_EQ(readings.work_offset[0], 0.25);
  EXPECT_DOUBLE_EQ(readings.work_offset[1], 0.125);
  EXPECT_DOUBLE_EQ(readings.work_offset[2], -0.4);

  status.units = Units::kUnknown;  // no position, so no offset either
  EXPECT_FALSE(readingsFrom(status, haasDefaults()).work_offset_valid);
}

TEST(MdcReadings, SpindleSpeedWhenPolledAndKnown)
{
  PollVariables vars = haasDefaults();
  MachineStatus status = statusAt(0, 0, 0, Units::kUnknown);
  EXPECT_FALSE(readingsFrom(status, vars).spindle_rpm);
  status.variables[3027] = 1200.0;
  ASSERT_TRUE(readingsFrom(status, vars).spindle_rpm);
  EXPECT_EQ(*readingsFrom(status, vars).spindle_rpm, 1200.0);
  vars.spindle = 0;
  EXPECT_FALSE(readingsFrom(status, vars).spindle_rpm);
}

TEST(MdcReadings, EstopFromTheStatusText)
{
  MachineStatus status;
  status.execution = Execution::kAlarm;
  status.status_text = "ALARM ON, e-stop pressed";
  EXPECT_EQ(estopFrom(status), Estop::kOn);
  status.status_text = "EMERGENCY STOP";
  EXPECT_EQ(estopFrom(status), Estop::kOn);
  status.status_text = "ALARM";  // an alarm that does not say which
  EXPECT_EQ(estopFrom(status), Estop::kUnknown);
  status.execution = Execution::kUnknown;
  status.status_text = "SOMETHING NEW";
  EXPECT_EQ(estopFrom(status), Estop::kUnknown);
  status.execution = Execution::kReady;
  status.status_text = "IDLE";
  EXPECT_EQ(estopFrom(status), Estop::kOff);
  status.execution = Execution::kPaused;
  status.status_text = "FEED HOLD";
  EXPECT_EQ(estopFrom(status), Estop::kOff);
}

TEST(MdcReadings, PollPlanNamesEachVariableOnce)
{
  PollVariables vars = haasDefaults();
  vars.extra = {100, 5021};
  vars.watched = {500, 100};
  PollPlan plan;
  vars.addTo(plan);
  EXPECT_EQ(plan.variables, (std::vector<int>{5021, 5022, 5023, 5041, 5042, 5043, 100, 500, 3027}));
  EXPECT_EQ(plan.slow_variables, std::vector<int>{4006});  // the unit from the control

  PollVariables fixed;
  fixed.position = {5021, 5022, 5023};
  fixed.units = UnitSetting::kMillimetre;
  fixed.spindle = 0;
  PollPlan fixed_plan;
  fixed.addTo(fixed_plan);
  EXPECT_EQ(fixed_plan.variables, (std::vector<int>{5021, 5022, 5023}));
  EXPECT_TRUE(fixed_plan.slow_variables.empty());
}

TEST(MdcReadings, PositionListsHaveThreeEntriesOrNone)
{
  PollVariables vars = haasDefaults();
  EXPECT_NO_THROW(vars.check("~position_variables"));
  EXPECT_EQ(vars.workOffsetAxes(), (std::vector<std::pair<int, int>>{{5021, 5041}, {5022, 5042}, {5023, 5043}}));
  vars.work.clear();
  EXPECT_NO_THROW(vars.check("~position_variables"));
  EXPECT_TRUE(vars.workOffsetAxes().empty());
  vars.position = {5021, 5022};
  EXPECT_THROW(vars.check("~position_variables"), ConfigError);
  vars.position.clear();
  vars.work = {5041};
  EXPECT_THROW(vars.check("~position_variables"), ConfigError);
}

TEST(MdcReadings, QueryPeriodsInMillisecondsAtLeastOne)
{
  const auto status = queryPeriod("~query_periods", "Q500", 0.25);
  EXPECT_EQ(status.first.text(), "?Q500");
  EXPECT_EQ(status.second, Milliseconds(250));
  EXPECT_EQ(queryPeriod("~query_periods", "Q600 5021", 0.0001).second, Milliseconds(1));
  EXPECT_EQ(queryPeriod("~query_periods", "Q303", 0).second, Milliseconds(0));
  EXPECT_THROW(queryPeriod("~query_periods", "Q500", -1), ConfigError);
  try
  {
    queryPeriod("~query_periods", "E100 1", 1);
    FAIL() << "a write accepted as a polled query";
  }
  catch (const ConfigError& e)
  {
    EXPECT_EQ(std::string(e.what()).rfind("~query_periods: ", 0), 0u) << e.what();
  }
}

// An answer of ~read_variable says what unit the value is in: a length in the control's G20/G21
// (as last polled, or as ~units fixes it), or that the unit is not known yet.
TEST(MdcReadings, TheUnitNoteNamesTheControlsUnitOrSaysItIsNotKnown)
{
  using mdc::Units;
  using mdc::UnitSetting;
  EXPECT_NE(mdc::unitNote(UnitSetting::kAuto, Units::kInch).find("a length (a position, an offset) in inch (G20"),
            std::string::npos);
  EXPECT_NE(mdc::unitNote(UnitSetting::kAuto, Units::kMillimetre).find("in mm (G21"), std::string::npos);
  EXPECT_NE(mdc::unitNote(UnitSetting::kAuto, Units::kUnknown).find("not known yet"), std::string::npos);
  EXPECT_NE(mdc::unitNote(UnitSetting::kMillimetre, Units::kUnknown).find("in mm (G21"), std::string::npos)
      << "~units fixes the unit";
}
