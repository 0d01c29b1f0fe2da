// BusRunner (bus_runner.h): inputs -> the step queue -> the session on the link's thread -> events.
#include "cnc_bridge/slave_bus/bus_runner.h"

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace slave_bus
{
BusRunner::BusRunner(BusSettings settings, const SafetySwitch& motion, BusListener& listener)
    : settings_(std::move(settings)),
      motion_(motion),
      listener_(listener),
      queue_(settings_.table.busSize(), settings_.max_queued_steps, settings_.command_delay),
      monitor_(settings_.table),
      link_("slave bus " + settings_.link.hardwareId(), linkFactory(settings_.link), settings_.backoff)
{
  queue_.close();  // until the link is up: nothing waits to be sent when it opens
}

BusRunner::~BusRunner()
{
  stop();
}

void BusRunner::start()
{
  link_.start([this](Transport& port) { run(port); },
              [this](LinkState state, const std::string& why) { onLinkState(state, why); });
}

void BusRunner::stop()
{
  queue_.stop();  // ends the I/O thread's wait for a step
  link_.stop();   // interrupts the port, ends the session, joins the thread
}

// ---- inputs ---------------------------------------------------------------------------------------

bool BusRunner::submitFrame(const std::vector<std::pair<uint8_t, std::vector<uint8_t>>>& payloads)
{
  StepPayloads step;
  try
  {
    step = settings_.table.framePayloads(payloads);
  }
  catch (const ProtocolError& e)
  {
    return refuse(std::string("bus/frame refused: ") + e.what());
  }
  // Under the gate: a disable comes wholly before the check (refused) or after the step is queued.
  const auto gate = motion_.gate();
  for (const auto& [address, data] : payloads)
  {
    if (!data.empty() && !motion_.enabled() && settings_.table.startsMotion(address))
    {
      return refuse("bus/frame refused: " +
                    motion_.refusal("address " + std::to_string(address) + " (an axis, tool or unconfigured slave)"));
    }
  }
  return queue_.pushFrame(std::move(step)) || refuseNotQueued("bus/frame");
}

bool BusRunner::submitCommand(size_t index, const std::vector<double>& values, const std::vector<uint8_t>& data)
{
  const SlaveConfig& slave = settings_.table.slaves().at(index);
  const std::string input = "slaves/" + slave.name + "/command";
  const auto gate = motion_.gate();
  if (startsMotion(slave.role) && !motion_.enabled())
  {
    return refuse(input + " refused: " + motion_.refusal("slave " + slave.name + " (it moves or cuts)"));
  }
  std::vector<uint8_t> payload;
  try
  {
    payload = settings_.table.commandPayload(index, values, data);
  }
  catch (const Error& e)
  {
    return refuse(input + " refused: " + e.what());
  }
  return queue_.pushCommand(slave.address - 1u, std::move(payload)) || refuseNotQueued(input);
}

bool BusRunner::refuse(const std::string& why)
{
  monitor_.refused();
  listener_.onRefused(why);
  return false;
}

/// The queue took nothing: the link is down (closed queue), or it is full.
bool BusRunner::refuseNotQueued(const std::string& input)
{
  if (!queue_.isOpen())
  {
    return refuse(input + " refused: the slave bus link is not up (" + settings_.link.hardwareId() +
                  "); nothing is kept to be sent when it returns");
  }
  return refuse(input + " refused: " + std::to_string(queue_.size()) +
                " steps already queued (~max_queued_steps): step refused");
}

// ---- the link -------------------------------------------------------------------------------------

/// The queue is open only while the link is up: steps that waited through an outage would move the
/// machine when the link returns, long after they were asked for, so they are dropped (counted and
/// told) and inputs meanwhile are refused.
void BusRunner::onLinkState(LinkState state, const std::string& why)
{
  if (state == LinkState::kUp)
  {
    queue_.open();
  }
  else if (const size_t dropped = queue_.close(); dropped > 0)
  {
    monitor_.droppedWithLink(dropped);
    listener_.onStepsDropped(dropped);
  }
  listener_.onLink(state, why);
}

/// The session on the open port (the link's thread): sends queued steps one at a time and reads
/// what comes back, until the port fails or the runner stops.
void BusRunner::run(Transport& port)
{
  BusSession session(port, settings_.framing, settings_.table.busSize(), settings_.resync_gap, settings_.table.wire());
  StepPayloads step;
  for (;;)
  {
    // Idle, the thread waits on the queue, not on the port: a new step leaves at once. What the
    // master writes meanwhile (late answers, status) waits in the port and is read right after.
    if (queue_.take(step, Milliseconds(20)))
    {
      sendStep(session, step);
      continue;
    }
    if (queue_.stopped())
    {
      return;
    }
    try
    {
      handle(session.poll(Milliseconds(0)));
    }
    catch (const Error&)
    {
      monitor_.sessionStats(session.stats());  // the bytes up to the failure count too
      throw;                                   // the link reopens the port after a backoff
    }
    monitor_.sessionStats(session.stats());
  }
}

void BusRunner::sendStep(BusSession& session, const StepPayloads& step)
{
  listener_.onExecution(true);
  BusSession::StepResult result;
  try
  {
    result = session.step(step, settings_.reply_timeout);
  }
  catch (const ProtocolError& e)
  {
    refuse(std::string("step not sent: ") + e.what());
    return;
  }
  catch (const Error& e)
  {
    refuse(std::string("step lost with the link (send it again once the link is up): ") + e.what());
    throw;  // the link reopens the port after a backoff
  }
  handle(result.replies);
  handle(result.master_status);
  monitor_.stepSent(step, result.missing, session.stats());
  if (queue_.size() == 0)
  {
    listener_.onExecution(false);
  }
}

void BusRunner::handle(const std::vector<UplinkRecord>& records)
{
  for (const auto& record : records)
  {
    if (record.address == 0)
    {
      listener_.onMasterStatus(monitor_.masterStatus(record));  // counted whether or not it is logged
      continue;
    }
    const int index = settings_.table.indexOf(record.address);
    if (index < 0)
    {
      monitor_.reply(-1, true);
      continue;
    }
    reply(static_cast<size_t>(index), record);
  }
}

void BusRunner::reply(size_t index, const UplinkRecord& record)
{
  const SlaveConfig& slave = settings_.table.slaves()[index];
  SlaveReply reply;
  reply.index = index;
  reply.data = record.payload;
  try
  {
    reply.values = settings_.table.replyValues(index, record.payload);
    reply.decoded = true;
  }
  catch (const ProtocolError&)
  {
    reply.decoded = false;
  }
  monitor_.reply(static_cast<int>(index), reply.decoded);
  if (isAxis(slave.role) && reply.values.size() == 1)
  {
    axis_seen_.insert(slave.role);
    reply.axis_update = true;
    reply.all_axes_known = axis_seen_.size() == settings_.table.axisCount();
  }
  listener_.onReply(reply);
}
}  // namespace slave_bus
}  // namespace cnc_bridge
