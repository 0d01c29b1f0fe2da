// QueryScheduler, MdcMonitor and MdcPoller (see mdc_monitor.h).
#include "cnc_bridge/mdc/mdc_monitor.h"

#include <algorithm>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge
{
namespace mdc
{
namespace
{
// Haas system variable #4006: modal group 6 of the last block, 20 (G20, inch) or 21 (G21, mm).
constexpr int kUnitsVariable = 4006;

ClientStats sum(const ClientStats& a, const ClientStats& b)
{
  ClientStats s;
  s.sent = a.sent + b.sent;
  s.answered = a.answered + b.answered;
  s.unanswered = a.unanswered + b.unanswered;
  s.rejected = a.rejected + b.rejected;
  s.foreign = a.foreign + b.foreign;
  s.dropped_lines = a.dropped_lines + b.dropped_lines;
  s.last_latency_ms = b.answered ? b.last_latency_ms : a.last_latency_ms;
  s.max_latency_ms = std::max(a.max_latency_ms, b.max_latency_ms);
  s.total_latency_ms = a.total_latency_ms + b.total_latency_ms;
  return s;
}
}  // namespace

void QueryScheduler::add(const Query& query, Milliseconds period)
{
  slots_.push_back(Slot{query, period, Clock::time_point(), false});
}

void QueryScheduler::reset(Clock::time_point now)
{
  for (auto& slot : slots_)
  {
    slot.due = now;
    slot.finished = false;
  }
}

std::optional<std::pair<Query, Clock::time_point>> QueryScheduler::next() const
{
  const Slot* best = nullptr;
  for (const auto& slot : slots_)
  {
    if (!slot.finished && (!best || slot.due < best->due))
    {
      best = &slot;
    }
  }
  if (!best)
  {
    return std::nullopt;
  }
  return std::make_pair(best->query, best->due);
}

void QueryScheduler::done(Clock::time_point now)
{
  Slot* best = nullptr;
  for (auto& slot : slots_)
  {
    if (!slot.finished && (!best || slot.due < best->due))
    {
      best = &slot;
    }
  }
  if (!best)
  {
    return;
  }
  if (best->period == kOnce)
  {
    best->finished = true;
    return;
  }
  best->due += best->period;
  if (best->due < now)
  {
    best->due = now;
  }
}

void MdcMonitor::setWorkOffsetAxes(const std::vector<std::pair<int, int>>& machine_work)
{
  axes_.clear();
  for (const auto& [machine, work] : machine_work)
  {
    AxisPair pair;
    pair.machine = machine;
    pair.work = work;
    axes_.push_back(pair);
  }
}

std::vector<CycleEventData> MdcMonitor::apply(const Reply& reply, Clock::time_point now)
{
  std::vector<CycleEventData> events;
  try
  {
    switch (reply.kind)
    {
      case ReplyKind::kSerialNumber:
        status_.serial_number = valueOf(reply);
        break;
      case ReplyKind::kSoftwareVersion:
        status_.software_version = valueOf(reply);
        break;
      case ReplyKind::kModel:
        status_.model = valueOf(reply);
        break;
      case ReplyKind::kMode:
        status_.mode_text = valueOf(reply);
        status_.mode = mapMode(status_.mode_text);
        break;
      case ReplyKind::kToolChanges:
        status_.tool_changes = integerOf(reply);
        break;
      case ReplyKind::kToolInUse:
        status_.tool = integerOf(reply);
        break;
      case ReplyKind::kPowerOnTime:
        status_.power_on_s = parseDuration(valueOf(reply));
        break;
      case ReplyKind::kMotionTime:
        status_.motion_s = parseDuration(valueOf(reply));
        break;
      case ReplyKind::kLastCycle:
        status_.last_cycle_s = parseDuration(valueOf(reply));
        break;
      case ReplyKind::kPreviousCycle:
        status_.previous_cycle_s = parseDuration(valueOf(reply));
        break;
      case ReplyKind::kPartsCounter1:
        status_.m30_counter1 = integerOf(reply);
        break;
      case ReplyKind::kPartsCounter2:
        status_.m30_counter2 = integerOf(reply);
        break;
      case ReplyKind::kProgramStatus:
        events = applyProgramStatus(toProgramStatus(reply), now);
        break;
      case ReplyKind::kMacro:
      {
        const auto [variable, value] = macroOf(reply);
        status_.variables[variable] = value;
        for (size_t axis = 0; axis < axes_.size() && axis < 3; ++axis)
        {
          auto& pair = axes_[axis];
          if (variable == pair.machine)
          {
            if (pair.work_since && pair.last_machine && *pair.last_machine == value)
            {
              status_.work_offset[axis] = value - *pair.work_since;
            }
            pair.last_machine = value;
            pair.work_since.reset();
          }
          else if (variable == pair.work && pair.last_machine)
          {
            pair.work_since = value;
          }
        }
        if (variable == kUnitsVariable)
        {
          status_.units = value == 20.0 ? Units::kInch : value == 21.0 ? Units::kMillimetre : Units::kUnknown;
        }
        break;
      }
      default:
        return events;
    }
  }
  catch (const ProtocolError& e)
  {
    CNC_LOG_WARN("MDC: ignored a malformed " << toString(reply.kind) << " reply: " << e.what());
    return events;
  }
  ++status_.updates;
  return events;
}

std::vector<CycleEventData> MdcMonitor::applyProgramStatus(const ProgramStatus& ps, Clock::time_point now)
{
  std::vector<CycleEventData> events;
  const Execution execution = mapExecution(ps.status);
  const std::optional<int64_t> previous_parts = status_.parts;
  status_.status_text = ps.status;
  status_.execution = execution;
  if (!ps.program.empty())
  {
    status_.program = ps.program;
  }
  if (ps.parts)
  {
    status_.parts = ps.parts;
  }
  const bool running = execution == Execution::kActive || execution == Execution::kPaused;
  const bool parts_rose = ps.parts && previous_parts && *ps.parts > *previous_parts;

  auto event = [&](CycleEventData::Type type, const std::string& text)
  {
    CycleEventData e;
    e.type = type;
    e.program = status_.program;
    e.part_count = status_.parts.value_or(-1);
    e.text = text;
    return e;
  };

  if (!seen_status_)
  {
    // Joining a machine mid-cycle: the cycle's start is unknown, its end will still be reported.
    seen_status_ = true;
    in_cycle_ = running;
    cycle_start_.reset();
    return events;
  }
  if (running && !in_cycle_)
  {
    in_cycle_ = true;
    cycle_start_ = now;
    events.push_back(event(CycleEventData::kCycleStart, "cycle start (" + ps.status + ")"));
  }
  else if (!running && in_cycle_)
  {
    in_cycle_ = false;
    if (execution == Execution::kAlarm)
    {
      events.push_back(event(CycleEventData::kAlarm, "alarm during the cycle (" + ps.status + ")"));
    }
    else
    {
      auto e =
          event(CycleEventData::kCycleEnd, parts_rose ? "cycle end, part counted" : "cycle end (" + ps.status + ")");
      if (cycle_start_)
      {
        e.cycle_time = std::chrono::duration<double>(now - *cycle_start_).count();
      }
      events.push_back(e);
    }
    cycle_start_.reset();
  }
  else if (!running && parts_rose)
  {
    events.push_back(event(CycleEventData::kPartCount,
                           "part counter rose from " + std::to_string(*previous_parts) + " with no cycle seen"));
  }
  return events;
}

QueryScheduler PollPlan::scheduler() const
{
  QueryScheduler scheduler;
  if (identity)
  {
    scheduler.add(q(100), QueryScheduler::kOnce);
    scheduler.add(q(101), QueryScheduler::kOnce);
    scheduler.add(q(102), QueryScheduler::kOnce);
  }
  scheduler.add(q(500), status_period);
  scheduler.add(q(104), status_period);
  for (int variable : variables)
  {
    scheduler.add(macroQuery(variable), variables_period);
  }
  for (int variable : slow_variables)
  {
    scheduler.add(macroQuery(variable), counters_period);
  }
  scheduler.add(q(201), counters_period);
  scheduler.add(q(303), counters_period);
  scheduler.add(q(304), counters_period);
  scheduler.add(q(402), counters_period);
  scheduler.add(q(200), counters_period);
  return scheduler;
}

MdcPoller::MdcPoller(PollPlan plan, Milliseconds reply_timeout, PortLock* port_lock)
    : plan_(std::move(plan)), reply_timeout_(reply_timeout), port_lock_(port_lock)
{
}

void MdcPoller::setWorkOffsetAxes(const std::vector<std::pair<int, int>>& machine_work)
{
  std::lock_guard<std::mutex> lock(mutex_);
  monitor_.setWorkOffsetAxes(machine_work);
}

void MdcPoller::notify(const Reply& reply)
{
  // Called with mutex_ held.
  const auto events = monitor_.apply(reply, Clock::now());
  if (listener_)
  {
    listener_(monitor_.status(), events);
  }
}

void MdcPoller::run(Transport& transport, StopSignal& stop)
{
  MdcClient client(transport);
  client.setForeignListener([this](const Reply& reply) { notify(reply); });
  QueryScheduler scheduler = plan_.scheduler();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    client_ = &client;
  }
  struct Detach
  {
    MdcPoller& self;
    MdcClient& client;
    ~Detach()
    {
      std::lock_guard<std::mutex> lock(self.mutex_);
      self.base_stats_ = sum(self.base_stats_, client.stats());
      self.stats_ = self.base_stats_;
      self.client_ = nullptr;
    }
  } detach{*this, client};

  scheduler.reset(Clock::now());
  unsigned unanswered_in_a_row = 0;
  while (!stop.stopped())
  {
    const auto next = scheduler.next();
    if (!next)
    {
      return;
    }
    const auto wait = std::chrono::duration_cast<Milliseconds>(next->second - Clock::now());
    if (wait.count() > 0 && stop.waitFor(wait))
    {
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (port_lock_ && port_lock_->heldElsewhere())
    {
      // A DNC transfer owns the serial line: stay silent until it ends.
      ++skipped_;
      scheduler.done(Clock::now());
      continue;
    }
    ++polls_;
    try
    {
      const Reply reply = client.request(next->first, reply_timeout_);
      unanswered_in_a_row = 0;
      notify(reply);
    }
    catch (const TimeoutError& e)
    {
      CNC_LOG_DEBUG(e.what());
      if (plan_.max_unanswered > 0 && ++unanswered_in_a_row >= plan_.max_unanswered)
      {
        stats_ = sum(base_stats_, client.stats());
        throw LinkError("MDC " + transport.describe() + ": no reply to " + std::to_string(unanswered_in_a_row) +
                        " queries in a row");
      }
    }
    scheduler.done(Clock::now());
    stats_ = sum(base_stats_, client.stats());
  }
}

void MdcPoller::withClient(const std::function<void(MdcClient&)>& action)
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (!client_)
  {
    throw LinkError("MDC: not connected");
  }
  if (port_lock_ && port_lock_->heldElsewhere())
  {
    throw LinkError("MDC: a DNC transfer holds the serial port (" + port_lock_->lockFile() + "); try again after it");
  }
  action(*client_);
  stats_ = sum(base_stats_, client_->stats());
}

MachineStatus MdcPoller::status() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return monitor_.status();
}

ClientStats MdcPoller::stats() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

uint64_t MdcPoller::skippedForPortLock() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return skipped_;
}

uint64_t MdcPoller::polls() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return polls_;
}
}  // namespace mdc
}  // namespace cnc_bridge
