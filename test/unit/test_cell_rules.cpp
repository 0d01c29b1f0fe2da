// The cell's rules (cnc_bridge/cell/cell_rules.h): an exhaustive table of every field and its
// unknown/stale values, the settle time and the lease, then random sequences (machine states, link
// drops, alarms mid-cycle, clock jumps) against an independent oracle: no unsafe entry is granted
// and no lease outlives a broken condition.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "cnc_bridge/cell/cell_rules.h"

using namespace cnc_bridge::cell;

namespace
{
const double kNaN = std::numeric_limits<double>::quiet_NaN();

MachineReport safeReport()
{
  MachineReport report;
  report.link = Link::Up;
  report.execution = Execution::Ready;
  report.estop = Estop::Off;
  report.spindle_rpm = 0.0;
  report.door = Door::Open;
  return report;
}

// The oracle: written from the words, field by field, not from the implementation.
bool fieldsSafe(const MachineReport& r, const MachineRules& rules)
{
  const bool link = r.link == Link::Up;
  const bool estop = r.estop == Estop::Off;
  const bool execution = r.execution == Execution::Ready || r.execution == Execution::Stopped;
  const bool spindle = !std::isnan(r.spindle_rpm) && std::fabs(r.spindle_rpm) < rules.spindle_stopped_rpm;
  const bool door = !rules.reports_door || r.door == Door::Open;
  return link && estop && execution && spindle && door;
}
}  // namespace

TEST(CellRulesTable, EveryFieldAndAgeCombination)
{
  const Link links[] = {Link::Down, Link::Connecting, Link::Up};
  const Execution executions[] = {Execution::Unknown, Execution::Ready,   Execution::Active,
                                  Execution::Paused,  Execution::Stopped, Execution::Alarm};
  const Estop estops[] = {Estop::Unknown, Estop::Off, Estop::On};
  const double spindles[] = {kNaN, 0.0, 0.4, 0.5, -0.4, 1200.0, -1200.0, std::numeric_limits<double>::infinity()};
  const Door doors[] = {Door::Unknown, Door::Open, Door::Closed, Door::Unlatched};
  MachineRules rules;
  rules.state_period_s = 0.5;
  rules.stale_factor = 4.0;  // stale beyond 2 s
  const double ages[] = {-0.001, 0.0, 1.0, 2.0, 2.001, 1e9, kNaN};
  int safe_cases = 0;
  for (bool reports_door : {false, true})
  {
    rules.reports_door = reports_door;
    for (Link link : links)
      for (Execution execution : executions)
        for (Estop estop : estops)
          for (double spindle : spindles)
            for (Door door : doors)
              for (double age : ages)
              {
                MachineReport report{link, execution, estop, spindle, door};
                const bool fresh = !std::isnan(age) && age >= 0.0 && age <= 2.0;
                const bool expected = fresh && fieldsSafe(report, rules);
                const Verdict verdict = judgeReport(report, age, rules);
                ASSERT_EQ(verdict.safe, expected)
                    << "link " << int(link) << " execution " << int(execution) << " estop " << int(estop) << " spindle "
                    << spindle << " door " << int(door) << " reports_door " << reports_door << " age " << age << ": "
                    << verdict.reason;
                ASSERT_EQ(verdict.reason.empty(), verdict.safe) << "a refusal says why";
                safe_cases += expected;
              }
  }
  // Safe: link up, estop off, READY or STOPPED, spindle 0/0.4/-0.4, ages 0/1/2; door any (3*4)
  // without a door report, door open (3) with one.
  EXPECT_EQ(safe_cases, 2 * 3 * 3 * (4 + 1));
}

TEST(CellRulesTable, ReasonNamesTheField)
{
  MachineRules rules;
  rules.reports_door = true;
  auto reason_with = [&](auto change)
  {
    MachineReport report = safeReport();
    change(report);
    return judgeReport(report, 0.0, rules).reason;
  };
  EXPECT_EQ(reason_with([](MachineReport& r) { r.link = Link::Down; }), "link down");
  EXPECT_EQ(reason_with([](MachineReport& r) { r.estop = Estop::Unknown; }), "emergency stop unknown");
  EXPECT_EQ(reason_with([](MachineReport& r) { r.estop = Estop::On; }), "emergency stop on");
  EXPECT_EQ(reason_with([](MachineReport& r) { r.execution = Execution::Paused; }), "execution PAUSED (in a cycle)");
  EXPECT_EQ(reason_with([](MachineReport& r) { r.execution = Execution::Alarm; }), "execution ALARM");
  EXPECT_EQ(reason_with([](MachineReport& r) { r.spindle_rpm = kNaN; }), "spindle speed unknown");
  EXPECT_EQ(reason_with([](MachineReport& r) { r.spindle_rpm = 800; }), "spindle turning");
  EXPECT_EQ(reason_with([](MachineReport& r) { r.door = Door::Unknown; }), "door unknown");
  EXPECT_EQ(reason_with([](MachineReport& r) { r.door = Door::Closed; }), "door closed");
  EXPECT_NE(judgeReport(safeReport(), 10.0, rules).reason.find("stale"), std::string::npos);
  EXPECT_NE(judgeReport(safeReport(), -1.0, rules).reason.find("clock"), std::string::npos);
}

TEST(CellRules, InvalidRulesAndNamesAreRefused)
{
  CellRules cell;
  MachineRules bad;
  bad.state_period_s = 0.0;
  EXPECT_THROW(cell.addMachine("m", bad), std::invalid_argument);
  bad = MachineRules{};
  bad.stale_factor = kNaN;
  EXPECT_THROW(cell.addMachine("m", bad), std::invalid_argument);
  cell.addMachine("m", MachineRules{});
  EXPECT_THROW(cell.addMachine("m", MachineRules{}), std::invalid_argument);
  EXPECT_THROW(cell.addMachine("", MachineRules{}), std::invalid_argument);
  EXPECT_THROW(cell.report("other", safeReport(), 0.0), std::invalid_argument);
  EXPECT_FALSE(cell.requestEntry("m", "", 0.0).safe);
}

TEST(CellRules, NoStateIsUnsafeAndSafeOnlyAfterSettling)
{
  CellRules cell;
  MachineRules rules;
  rules.settle_s = 2.0;
  rules.state_period_s = 1.0;
  cell.addMachine("m", rules);
  EXPECT_EQ(cell.verdict("m", 0.0).reason, "no state received");
  cell.report("m", safeReport(), 10.0);
  EXPECT_FALSE(cell.requestEntry("m", "r1", 10.0).safe);
  cell.report("m", safeReport(), 11.0);
  EXPECT_FALSE(cell.requestEntry("m", "r1", 11.5).safe);
  cell.report("m", safeReport(), 12.0);
  EXPECT_TRUE(cell.requestEntry("m", "r1", 12.0).safe);
  EXPECT_EQ(cell.leaseHolder("m").value_or(""), "r1");
}

TEST(CellRules, GapLongerThanStaleLimitRestartsSettling)
{
  CellRules cell;
  MachineRules rules;
  rules.settle_s = 1.0;
  cell.addMachine("m", rules);
  cell.report("m", safeReport(), 0.0);
  cell.report("m", safeReport(), 100.0);  // unknown for 97 s in between
  EXPECT_FALSE(cell.verdict("m", 100.0).safe);
  cell.report("m", safeReport(), 101.0);
  EXPECT_TRUE(cell.verdict("m", 101.0).safe);
}

TEST(CellRulesLease, OneRobotAtATimeAndWithdrawnWhenAConditionBreaks)
{
  CellRules cell;
  MachineRules rules;
  rules.settle_s = 0.0;
  cell.addMachine("m", rules);
  cell.report("m", safeReport(), 0.0);
  ASSERT_TRUE(cell.requestEntry("m", "r1", 0.0).safe);
  EXPECT_EQ(cell.requestEntry("m", "r2", 0.0).reason, "entry held by robot 'r1'");
  EXPECT_TRUE(cell.requestEntry("m", "r1", 0.1).safe);
  EXPECT_TRUE(cell.withdrawBroken(0.5).empty());
  MachineReport cycle = safeReport();
  cycle.execution = Execution::Active;
  cell.report("m", cycle, 0.6);
  const auto withdrawn = cell.withdrawBroken(0.6);
  ASSERT_EQ(withdrawn.size(), 1u);
  EXPECT_EQ(withdrawn[0].robot, "r1");
  EXPECT_EQ(withdrawn[0].reason, "execution ACTIVE");
  EXPECT_FALSE(cell.leaseHolder("m"));
  EXPECT_FALSE(cell.release("m", "r1"));
}

TEST(CellRulesLease, WithdrawnWhenTheStateGoesStaleWithoutAnyReport)
{
  CellRules cell;
  cell.addMachine("m", MachineRules{});  // period 1 s, factor 3
  cell.report("m", safeReport(), 0.0);
  cell.report("m", safeReport(), 1.0);
  ASSERT_TRUE(cell.requestEntry("m", "r1", 1.0).safe);
  EXPECT_TRUE(cell.withdrawBroken(4.0).empty());
  const auto withdrawn = cell.withdrawBroken(4.01);
  ASSERT_EQ(withdrawn.size(), 1u);
  EXPECT_NE(withdrawn[0].reason.find("stale"), std::string::npos);
}

TEST(CellRulesLease, AClockJumpBackwardsWithdrawsEveryLease)
{
  CellRules cell;
  MachineRules rules;
  rules.settle_s = 0.0;
  cell.addMachine("a", rules);
  cell.addMachine("b", rules);
  cell.report("a", safeReport(), 50.0);
  cell.report("b", safeReport(), 50.0);
  ASSERT_TRUE(cell.requestEntry("a", "r1", 50.0).safe);
  ASSERT_TRUE(cell.requestEntry("b", "r2", 50.0).safe);
  EXPECT_EQ(cell.withdrawBroken(49.0).size(), 2u);
  EXPECT_FALSE(cell.requestEntry("a", "r1", 49.0).safe);
}

// Random sequences against the oracle: per machine, the last report, when it came, and since when
// it has been continuously safe (no unsafe report, no gap beyond the stale limit, no clock jump).
namespace
{
struct OracleMachine
{
  MachineRules rules;
  bool has_report = false;
  MachineReport last;
  double received = 0.0;
  bool has_safe_run = false;
  double safe_since = 0.0;
};

bool oracleSafeNow(const OracleMachine& m, double now)
{
  if (!m.has_report || !m.has_safe_run)
    return false;
  const double age = now - m.received;
  if (age < 0.0 || age > m.rules.state_period_s * m.rules.stale_factor)
    return false;
  return fieldsSafe(m.last, m.rules) && now - m.safe_since >= m.rules.settle_s;
}

MachineReport randomReport(std::mt19937& random)
{
  // Mostly safe, so that entries are granted and then broken by one field at a time.
  MachineReport report = safeReport();
  std::uniform_int_distribution<int> pick(0, 9);
  switch (pick(random))
  {
    case 0:
      report.link = pick(random) < 5 ? Link::Down : Link::Connecting;
      break;  // link drop
    case 1:
      report.execution = Execution::Alarm;
      break;  // alarm mid-cycle
    case 2:
      report.execution = static_cast<Execution>(pick(random) % 6);
      break;
    case 3:
      report.estop = static_cast<Estop>(pick(random) % 3);
      break;
    case 4:
      report.spindle_rpm = pick(random) < 3 ? kNaN : 10.0 * pick(random);
      break;
    case 5:
      report.door = static_cast<Door>(pick(random) % 4);
      break;
    default:
      break;
  }
  if (pick(random) == 0)
    report.execution = Execution::Stopped;
  return report;
}
}  // namespace

class CellRulesProperty : public ::testing::TestWithParam<unsigned>
{
};

TEST_P(CellRulesProperty, NeverGrantsAnUnsafeEntryNorKeepsABrokenLease)
{
  std::mt19937 random(GetParam());
  const std::vector<std::string> names = {"haas", "router", "lathe"};
  const std::vector<std::string> robots = {"r1", "r2"};
  CellRules cell;
  std::map<std::string, OracleMachine> oracle;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (std::size_t i = 0; i < names.size(); ++i)
  {
    MachineRules rules;
    rules.state_period_s = 0.2 + 0.3 * static_cast<double>(i);
    rules.stale_factor = 2.0 + static_cast<double>(i);
    rules.settle_s = 0.5 * static_cast<double>(i);
    rules.reports_door = i != 1;
    cell.addMachine(names[i], rules);
    oracle[names[i]].rules = rules;
  }
  double now = 1000.0;
  int granted = 0, withdrawn_count = 0;
  for (int step = 0; step < 20000; ++step)
  {
    const double roll = unit(random);
    if (roll < 0.02)
    {
      now -= 5.0 * unit(random);  // clock jump backwards
      for (auto& entry : oracle)
        entry.second.has_report = entry.second.has_safe_run = false;
    }
    else if (roll < 0.04)
    {
      now += 20.0 * unit(random);  // clock jump forwards (or a long stall)
    }
    else
    {
      now += 0.3 * unit(random);
    }
    const std::string& name = names[random() % names.size()];
    const std::string& robot = robots[random() % robots.size()];
    const double action = unit(random);
    if (action < 0.6)
    {
      const MachineReport report = randomReport(random);
      cell.report(name, report, now);
      OracleMachine& m = oracle[name];
      const bool gap = m.has_report && now - m.received > m.rules.state_period_s * m.rules.stale_factor;
      const bool backwards = m.has_report && now < m.received;
      if (!fieldsSafe(report, m.rules) || gap || backwards)
        m.has_safe_run = false;
      if (fieldsSafe(report, m.rules) && !m.has_safe_run)
      {
        m.has_safe_run = true;
        m.safe_since = now;
      }
      m.has_report = true;
      m.last = report;
      m.received = now;
    }
    else if (action < 0.9)
    {
      const Verdict answer = cell.requestEntry(name, robot, now);
      if (answer.safe)
      {
        ++granted;
        ASSERT_TRUE(oracleSafeNow(oracle[name], now))
            << "step " << step << ": unsafe entry granted on " << name << " now " << now << " received "
            << oracle[name].received << " safe_since " << oracle[name].safe_since << " run "
            << oracle[name].has_safe_run << " report " << oracle[name].has_report;
      }
    }
    else
    {
      cell.release(name, robot);
    }
    withdrawn_count += static_cast<int>(cell.withdrawBroken(now).size());
    for (const auto& entry : oracle)
    {
      if (cell.leaseHolder(entry.first))
      {
        ASSERT_TRUE(oracleSafeNow(entry.second, now)) << "step " << step << ": lease kept on unsafe " << entry.first;
      }
    }
  }
  // The sequence exercised both sides: entries granted and leases withdrawn.
  EXPECT_GT(granted, 100);
  EXPECT_GT(withdrawn_count, 20);
}

INSTANTIATE_TEST_SUITE_P(Seeds, CellRulesProperty, ::testing::Values(1u, 7u, 42u, 2026u, 90210u));
