// QueryScheduler, MdcMonitor and MdcPoller (see mdc_monitor.h).
#include "cnc_bridge/mdc/mdc_monitor.h"

#include <algorithm>
#include <cmath>
#include <limits>

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
  s.text_lines = a.text_lines + b.text_lines;
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
    slot.rejections = 0;
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

QueryScheduler::Slot* QueryScheduler::current()
{
  Slot* best = nullptr;
  for (auto& slot : slots_)
  {
    if (!slot.finished && (!best || slot.due < best->due))
    {
      best = &slot;
    }
  }
  return best;
}

void QueryScheduler::done(Clock::time_point now)
{
  Slot* best = current();
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

void QueryScheduler::unanswered(Clock::time_point now, Milliseconds retry_after)
{
  Slot* best = current();
  if (best && best->period == kOnce)
  {
    // Asked once per connection, so a lost reply must not lose the value for the whole connection.
    best->due = now + retry_after;
    return;
  }
  done(now);
}

void QueryScheduler::rejected(Clock::time_point now, Milliseconds retry_after)
{
  Slot* best = current();
  if (best && best->period == kOnce && best->rejections++ == 0)
  {
    // The Haas NGC MDC page: "For the initial connection, ?Q100 may have to be entered twice."
    // The first answer on a fresh connection can be a rejection; only a second one is final.
    best->due = now + retry_after;
    return;
  }
  done(now);
}

std::vector<std::pair<Query, Milliseconds>> QueryScheduler::plan() const
{
  std::vector<std::pair<Query, Milliseconds>> result;
  for (const auto& slot : slots_)
  {
    result.emplace_back(slot.query, slot.period);
  }
  return result;
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
        const MacroReading reading = macroOf(reply);
        if (!reading.variable)
        {
          // An NGC "MACRO, value" that answered another client's query: which variable it holds
          // cannot be told, so it is not folded in.
          return events;
        }
        const int variable = *reading.variable;
        const double value = reading.value;
        status_.variables[variable] = value;
        status_.variable_errors.erase(variable);
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
    if (reply.kind == ReplyKind::kMacro && reply.answered && reply.answered->code == 600 && reply.answered->argument)
    {
      variableFailed(static_cast<int>(*reply.answered->argument), std::string("malformed reply: ") + e.what());
    }
    return events;
  }
  ++status_.updates;
  return events;
}

namespace
{
// Equal as published values: the same number, or both unknown (NaN).
bool sameValues(const std::vector<double>& a, const std::vector<double>& b)
{
  if (a.size() != b.size())
    return false;
  for (size_t i = 0; i < a.size(); ++i)
  {
    if (!(a[i] == b[i] || (std::isnan(a[i]) && std::isnan(b[i]))))
      return false;
  }
  return true;
}
}  // namespace

std::optional<std::vector<double>> VariableWatch::update(const MachineStatus& status)
{
  std::vector<double> values;
  values.reserve(numbers_.size());
  for (int n : numbers_)
  {
    const auto value = status.variables.find(n);
    if (value != status.variables.end())
      values.push_back(value->second);
    else if (status.variable_errors.count(n))
      values.push_back(std::numeric_limits<double>::quiet_NaN());
    else
      return std::nullopt;  // not polled yet on this connection
  }
  if (published_ && sameValues(*published_, values))
    return std::nullopt;
  published_ = values;
  return values;
}

std::optional<std::vector<double>> VariableWatch::linkLost()
{
  const std::vector<double> unknown(numbers_.size(), std::numeric_limits<double>::quiet_NaN());
  if (!published_ || sameValues(*published_, unknown))
    return std::nullopt;
  published_ = unknown;
  return unknown;
}

std::string VariableWatch::errors(const MachineStatus& status) const
{
  std::string text;
  for (int n : numbers_)
  {
    const auto error = status.variable_errors.find(n);
    if (error != status.variable_errors.end())
      text += (text.empty() ? "#" : "; #") + std::to_string(n) + ": " + error->second;
  }
  return text;
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
  std::vector<std::pair<Query, Milliseconds>> entries;
  if (identity)
  {
    for (int code : {100, 101, 102})
    {
      entries.emplace_back(q(code), QueryScheduler::kOnce);
    }
  }
  entries.emplace_back(q(500), status_period);
  entries.emplace_back(q(104), status_period);
  for (int variable : variables)
  {
    entries.emplace_back(macroQuery(variable), variables_period);
  }
  for (int variable : slow_variables)
  {
    entries.emplace_back(macroQuery(variable), counters_period);
  }
  for (int code : {201, 303, 304, 402, 200})
  {
    entries.emplace_back(q(code), counters_period);
  }
  // A per-query period replaces its group's; 0 there removes the query (in the groups 0 means
  // "as often as possible").
  std::vector<bool> keep(entries.size(), true);
  for (const auto& [query, period] : query_periods)
  {
    bool found = false;
    for (size_t i = 0; i < entries.size(); ++i)
    {
      if (entries[i].first == query)
      {
        entries[i].second = period;
        keep[i] = period != Milliseconds(0);
        found = true;
      }
    }
    if (!found && period != Milliseconds(0))
    {
      entries.emplace_back(query, period);
      keep.push_back(true);
    }
  }
  QueryScheduler scheduler;
  for (size_t i = 0; i < entries.size(); ++i)
  {
    if (keep[i])
    {
      scheduler.add(entries[i].first, entries[i].second);
    }
  }
  return scheduler;
}

Query parseQueryKey(const std::string& key)
{
  std::string text = key;
  const size_t first = text.find_first_not_of(' ');
  text.erase(0, first == std::string::npos ? text.size() : first);
  if (!text.empty() && text[0] != '?')
  {
    text.insert(0, "?");
  }
  std::replace(text.begin(), text.end(), '_', ' ');  // "Q600_5021": a key without a space
  const auto query = parseReadOnlyQuery(text);
  if (!query)
  {
    throw ConfigError("'" + key + "' is not a read-only query such as Q500 or \"Q600 5021\"");
  }
  return *query;
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
  auto events = monitor_.apply(reply, Clock::now());
  const bool cycle_end = std::any_of(events.begin(), events.end(),
                                     [](const CycleEventData& e) { return e.type == CycleEventData::kCycleEnd; });
  if (hold_cycle_ends_ && (cycle_end || !held_events_.empty()))
  {
    // Held until the control's cycle time is asked (deliverHeldEvents), in order.
    held_events_.insert(held_events_.end(), events.begin(), events.end());
    events.clear();
  }
  if (listener_)
  {
    listener_(monitor_.status(), events);
  }
}

void MdcPoller::deliverHeldEvents(MdcClient& client)
{
  // Called with mutex_ held (and the port lock, if any).
  while (!held_events_.empty())
  {
    std::vector<CycleEventData> events;
    events.swap(held_events_);
    std::optional<double> control_time;
    hold_cycle_ends_ = false;  // replies to the Q303 request go straight to the listener
    struct Rehold
    {
      bool& hold;
      ~Rehold() { hold = true; }
    } rehold{hold_cycle_ends_};
    try
    {
      const Reply reply = client.request(q(303), reply_timeout_);
      notify(reply);
      if (reply.kind == ReplyKind::kLastCycle)
      {
        control_time = monitor_.status().last_cycle_s;
      }
    }
    catch (const TimeoutError& e)
    {
      CNC_LOG_DEBUG("MDC: no last cycle time at the cycle end, the measured one is used: " << e.what());
    }
    catch (const LinkError&)
    {
      if (listener_)
      {
        listener_(monitor_.status(), events);  // with the measured cycle time
      }
      throw;
    }
    for (auto& e : events)
    {
      if (e.type == CycleEventData::kCycleEnd && control_time)
      {
        e.cycle_time = *control_time;
        e.text += ", cycle time from the control";
      }
    }
    if (listener_)
    {
      listener_(monitor_.status(), events);
    }
  }
}

// Holds the port lock for one use of the line; releases it when it goes out of scope.
class MdcPoller::PortUse
{
 public:
  explicit PortUse(PortLock* lock) : lock_(lock) {}
  ~PortUse()
  {
    if (lock_)
    {
      lock_->unlock();
    }
  }
  PortUse(const PortUse&) = delete;
  PortUse& operator=(const PortUse&) = delete;

 private:
  PortLock* lock_;
};

bool MdcPoller::takePort(MdcClient& client)
{
  if (!port_lock_)
  {
    return true;
  }
  if (!port_lock_->tryLockForQuery())
  {
    return false;
  }
  const uint64_t generation = port_lock_->generation();
  const bool used_elsewhere = port_generation_ && *port_generation_ != generation;
  port_generation_ = generation;
  if (used_elsewhere)
  {
    // A transfer used the line since our last query: its leftover bytes are not replies, and it
    // may have set the line up its own way (baud, data bits) on the shared device.
    ++regained_;
    try
    {
      // On a line that also carries DPRNT, what arrived meanwhile may be the program's lines,
      // printed once the transfer ended: kept (the transfer's own leftovers, NAK ACK CAN, are
      // control bytes the text demultiplexer drops).
      if (!text_listener_)
        client.discardInput();
      if (port_regained_)
      {
        port_regained_(client.transport());
      }
    }
    catch (...)
    {
      port_lock_->unlock();
      throw;
    }
  }
  return true;
}

void MdcPoller::run(Transport& transport, StopSignal& stop)
{
  MdcClient client(transport);
  client.setForeignListener([this](const Reply& reply) { notify(reply); });
  if (text_listener_)
  {
    client.setTextListener(text_listener_);
  }
  QueryScheduler scheduler = plan_.scheduler();
  attach(client);
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
      self.hold_cycle_ends_ = false;
      if (!self.held_events_.empty() && self.listener_)
      {
        self.listener_(self.monitor_.status(), self.held_events_);  // with the measured cycle time
      }
      self.held_events_.clear();
    }
  } detach{*this, client};

  // How long a poll waits before it tries a busy port again.
  constexpr Milliseconds kPortBusyRetry{50};
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
    if (wait.count() > 0 && waitForPoll(client, wait, stop))
    {
      return;
    }
    std::unique_lock<std::mutex> lock(mutex_);
    if (!takePort(client))
    {
      // A DNC transfer owns the serial line, or waits for it: stay silent until it ends. The query
      // stays due and goes first when the port is free.
      ++skipped_;
      lock.unlock();
      if (stop.waitFor(kPortBusyRetry))
      {
        return;
      }
      continue;
    }
    PortUse port(port_lock_);
    ++polls_;
    try
    {
      const Reply reply = client.request(next->first, reply_timeout_);
      unanswered_in_a_row = 0;
      if (reply.kind == ReplyKind::kUnknownQuery)
        noteVariableFailure(next->first, "rejected by the control (\"" + reply.line + "\")");
      notify(reply);
      if (reply.kind == ReplyKind::kUnknownQuery)
        scheduler.rejected(Clock::now(), plan_.counters_period);
      else
        scheduler.done(Clock::now());
      deliverHeldEvents(client);
    }
    catch (const TimeoutError& e)
    {
      CNC_LOG_DEBUG(e.what());
      if (noteVariableFailure(next->first, "no reply within " + std::to_string(reply_timeout_.count()) + " ms") &&
          listener_)
      {
        listener_(monitor_.status(), {});
      }
      scheduler.unanswered(Clock::now(), plan_.counters_period);
      if (plan_.max_unanswered > 0 && ++unanswered_in_a_row >= plan_.max_unanswered)
      {
        stats_ = sum(base_stats_, client.stats());
        throw LinkError("MDC " + transport.describe() + ": no reply to " + std::to_string(unanswered_in_a_row) +
                        " queries in a row: check that the control's Setting 143 (MDC port, NGC over TCP) is on "
                        "and is this port, or (Classic over RS-232) that Settings 11, 12, 37 and 13 match this "
                        "side's; `cnc_dnc doctor --port DEV` checks a serial port");
      }
      deliverHeldEvents(client);
    }
    stats_ = sum(base_stats_, client.stats());
  }
}

void MdcPoller::attach(MdcClient& client)
{
  std::lock_guard<std::mutex> lock(mutex_);
  client_ = &client;
  monitor_.forgetVariables();  // values of an earlier connection may be stale
  port_generation_.reset();    // a freshly opened port has our settings
  hold_cycle_ends_ = plan_.cycle_time_from_control;
  held_events_.clear();
}

bool MdcPoller::waitForPoll(MdcClient& client, Milliseconds wait, StopSignal& stop)
{
  if (!text_listener_)
  {
    return stop.waitFor(wait);
  }
  // The line carries DPRNT output too: read it while waiting, in slices with the port held, so
  // that each line is passed on as it comes and none is left in the buffer for a DNC transfer
  // (which would take it for noise) when the port changes hands.
  constexpr Milliseconds kSlice{50};
  const auto until = Clock::now() + wait;
  while (!stop.stopped())
  {
    const auto left = std::chrono::ceil<Milliseconds>(until - Clock::now());
    if (left.count() <= 0)
    {
      return false;
    }
    std::unique_lock<std::mutex> lock(mutex_);
    if (!takePort(client))
    {
      lock.unlock();
      if (stop.waitFor(std::min(left, kSlice)))
      {
        return true;
      }
      continue;
    }
    PortUse port(port_lock_);
    client.drainForeign(std::min(left, kSlice));
    stats_ = sum(base_stats_, client.stats());
  }
  return true;
}

bool MdcPoller::noteVariableFailure(const Query& query, const std::string& why)
{
  // Called with mutex_ held.
  if (query.letter != 'Q' || query.code != 600 || !query.argument)
    return false;
  monitor_.variableFailed(static_cast<int>(*query.argument), why);
  return true;
}

void MdcPoller::withClient(const std::function<void(MdcClient&)>& action)
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (!client_)
  {
    throw LinkError("MDC: not connected");
  }
  if (!takePort(*client_))
  {
    throw LinkError("MDC: a DNC transfer holds the serial port (" + port_lock_->lockFile() + "); try again after it");
  }
  PortUse port(port_lock_);
  action(*client_);
  deliverHeldEvents(*client_);
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

uint64_t MdcPoller::portRegained() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return regained_;
}

uint64_t MdcPoller::polls() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return polls_;
}
}  // namespace mdc
}  // namespace cnc_bridge
