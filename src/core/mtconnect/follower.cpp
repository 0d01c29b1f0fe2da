#include "cnc_bridge/mtconnect/follower.h"

#include <algorithm>
#include <cctype>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge::mtconnect
{
namespace
{
std::string percentEncoded(const std::string& text)
{
  static const char* hex = "0123456789ABCDEF";
  std::string out;
  for (unsigned char c : text)
  {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '~')
    {
      out += static_cast<char>(c);
    }
    else
    {
      out += '%';
      out += hex[c >> 4u];
      out += hex[c & 15u];
    }
  }
  return out;
}

// Retries of /current when the agent restarts again while we resynchronise.
constexpr int kResyncAttempts = 3;
}  // namespace

Follower::Follower(FollowerSettings settings, HttpClient& http, FollowerListener& listener)
    : settings_(std::move(settings)), http_(http), listener_(listener)
{
  if (settings_.count == 0)
    throw ConfigError("~count must be at least 1");
}

std::string Follower::probeTarget() const
{
  return settings_.device.empty() ? "/probe" : "/" + percentEncoded(settings_.device) + "/probe";
}

std::string Follower::currentTarget() const
{
  return settings_.device.empty() ? "/current" : "/" + percentEncoded(settings_.device) + "/current";
}

std::string Follower::sampleTarget(uint64_t from, bool streaming) const
{
  std::string target = settings_.device.empty() ? "/sample" : "/" + percentEncoded(settings_.device) + "/sample";
  target += "?from=" + std::to_string(from) + "&count=" + std::to_string(settings_.count);
  if (streaming)
  {
    target += "&interval=" + std::to_string(settings_.interval.count()) +
              "&heartbeat=" + std::to_string(std::max<long long>(1, settings_.heartbeat.count()));
  }
  return target;
}

FollowerStats Follower::stats() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

Document Follower::fetch(const std::string& target, const char* what)
{
  const Response response = http_.get(target, settings_.request_timeout);
  if (response.body.empty())
  {
    throw ProtocolError("the agent answered " + std::to_string(response.head.status) + " " + response.head.reason +
                        " with no document to " + what + " (GET " + target + ")");
  }
  return parseDocument(response.body, http_.limits().max_document_bytes);
}

void Follower::probe()
{
  const Document doc = fetch(probeTarget(), "the probe");
  if (doc.kind == DocumentKind::kError)
    throw ProtocolError("the agent refused the probe (GET " + probeTarget() + "): " + doc.errorText());
  if (doc.kind != DocumentKind::kDevices)
    throw ProtocolError("the agent answered the probe (GET " + probeTarget() + ") with no MTConnectDevices document");
  const Device& device = selectDevice(doc, settings_.device);
  if (!instance_.empty() && doc.header.instance_id != instance_)
  {
    const std::string what = "agent restarted (instanceId " + instance_ + " -> " + doc.header.instance_id + ")";
    withStats(
        [&](FollowerStats& s)
        {
          ++s.restarts;
          s.last_restart = what;
        });
    CNC_LOG_WARN("mtconnect: " << what);
    listener_.onDiscontinuity(what);
  }
  instance_ = doc.header.instance_id;
  device_name_ = device.name;
  next_ = 0;
  withStats(
      [&](FollowerStats& s)
      {
        s.instance_id = instance_;
        s.agent_version = doc.header.version;
      });
  listener_.onProbe(doc, device);
}

void Follower::resync()
{
  for (int attempt = 0; attempt < kResyncAttempts; ++attempt)
  {
    if (instance_.empty())
      probe();
    const Document doc = fetch(currentTarget(), "/current");
    if (doc.kind != DocumentKind::kStreams)
    {
      throw ProtocolError("the agent answered /current (GET " + currentTarget() + ") with " +
                          (doc.kind == DocumentKind::kError ? doc.errorText() : std::string("a probe")));
    }
    if (doc.header.instance_id != instance_)
    {
      // Restarted between the probe and /current: the probe no longer describes it.
      instance_.clear();
      withStats([&](FollowerStats& s) { ++s.restarts; });
      continue;
    }
    std::vector<Observation> observations;
    for (const auto& o : doc.observations)
    {
      if (o.device.empty() || o.device == device_name_)
        observations.push_back(o);
    }
    std::stable_sort(observations.begin(), observations.end(),
                     [](const Observation& a, const Observation& b) { return a.sequence < b.sequence; });
    next_ = doc.header.next_sequence;
    withStats(
        [&](FollowerStats& s)
        {
          ++s.documents;
          s.observations += observations.size();
          s.next_sequence = next_;
        });
    listener_.onObservations(observations, true);
    return;
  }
  throw ProtocolError("the agent restarted " + std::to_string(kResyncAttempts) + " times while it was read");
}

void Follower::gap(uint64_t lost, const std::string& what)
{
  withStats(
      [&](FollowerStats& s)
      {
        ++s.gaps;
        s.lost_observations += lost;
        s.last_gap = what;
      });
  CNC_LOG_WARN("mtconnect: " << what << "; reading /current again");
  listener_.onDiscontinuity(what);
}

Follower::Verdict Follower::handleStreams(const Document& doc)
{
  if (doc.header.instance_id != instance_)
  {
    const std::string what = "agent restarted (instanceId " + instance_ + " -> " + doc.header.instance_id + ")";
    withStats(
        [&](FollowerStats& s)
        {
          ++s.restarts;
          s.last_restart = what;
        });
    CNC_LOG_WARN("mtconnect: " << what << "; probing it again");
    listener_.onDiscontinuity(what);
    instance_.clear();  // resync() probes the new instance
    return Verdict::kResync;
  }
  if (doc.header.first_sequence > next_)
  {
    gap(doc.header.first_sequence - next_, "buffer overrun: the agent's oldest observation is " +
                                               std::to_string(doc.header.first_sequence) + ", sequences " +
                                               std::to_string(next_) + " to " +
                                               std::to_string(doc.header.first_sequence - 1) + " were lost");
    return Verdict::kResync;
  }
  std::vector<Observation> observations;
  for (const auto& o : doc.observations)
  {
    if ((o.device.empty() || o.device == device_name_) && o.sequence >= next_)
      observations.push_back(o);
  }
  // A document groups observations by component; what happened first comes first here.
  std::stable_sort(observations.begin(), observations.end(),
                   [](const Observation& a, const Observation& b) { return a.sequence < b.sequence; });
  next_ = std::max(next_, doc.header.next_sequence);
  withStats(
      [&](FollowerStats& s)
      {
        ++s.documents;
        s.observations += observations.size();
        s.next_sequence = next_;
      });
  if (!observations.empty())
    listener_.onObservations(observations, false);
  return Verdict::kContinue;
}

Follower::Verdict Follower::handle(const std::string& body, const char* what)
{
  const Document doc = parseDocument(body, http_.limits().max_document_bytes);
  if (doc.kind == DocumentKind::kError)
  {
    if (doc.hasError("OUT_OF_RANGE"))
    {
      gap(0,
          "buffer overrun: the agent no longer holds sequence " + std::to_string(next_) + " (" + doc.errorText() + ")");
      return Verdict::kResync;
    }
    throw ProtocolError(std::string("the agent refused ") + what + ": " + doc.errorText());
  }
  if (doc.kind != DocumentKind::kStreams)
    throw ProtocolError(std::string("the agent answered ") + what + " with a probe document");
  return handleStreams(doc);
}

void Follower::followStream(StopSignal& stop, bool& resync_needed)
{
  const std::string target = sampleTarget(next_, true);
  withStats(
      [&](FollowerStats& s)
      {
        ++s.streams;
        s.streaming = true;
      });
  HttpClient::StreamEnd end;
  try
  {
    end = http_.stream(target, settings_.heartbeat + settings_.request_timeout,
                       [&](std::string&& part)
                       {
                         if (stop.stopped())
                           return false;
                         resync_needed = handle(part, "the stream") == Verdict::kResync;
                         return !resync_needed;
                       });
  }
  catch (...)
  {
    withStats([](FollowerStats& s) { s.streaming = false; });
    throw;
  }
  withStats([](FollowerStats& s) { s.streaming = false; });
  if (end.multipart)
    return;  // the agent ended the stream (or we left it): the next one starts at next_
  // Not a stream: an agent (or a proxy) that does not stream answers once, or refuses.
  std::string why = "HTTP " + std::to_string(end.head.status) + " " + end.head.reason;
  try
  {
    const Document doc = parseDocument(end.body, http_.limits().max_document_bytes);
    if (doc.kind == DocumentKind::kError && doc.hasError("OUT_OF_RANGE"))
    {
      resync_needed = handle(end.body, "the stream") == Verdict::kResync;
      return;
    }
    if (doc.kind == DocumentKind::kStreams)
      resync_needed = handleStreams(doc) == Verdict::kResync;
    else if (doc.kind == DocumentKind::kError)
      why += ", " + doc.errorText();
  }
  catch (const ProtocolError& e)
  {
    why += ", " + std::string(e.what());
  }
  streaming_refused_ = true;
  CNC_LOG_WARN("mtconnect: the agent does not stream GET " << target << " (" << why << "); polling /sample every "
                                                           << settings_.poll_period.count() << " ms instead");
}

void Follower::pollOnce(bool& resync_needed)
{
  withStats([](FollowerStats& s) { ++s.polls; });
  const std::string target = sampleTarget(next_, false);
  const Response response = http_.get(target, settings_.request_timeout);
  if (response.body.empty())
  {
    throw ProtocolError("the agent answered " + std::to_string(response.head.status) + " " + response.head.reason +
                        " with no document (GET " + target + ")");
  }
  resync_needed = handle(response.body, "a /sample poll") == Verdict::kResync;
}

void Follower::follow(StopSignal& stop)
{
  if (instance_.empty())
    probe();
  resync();
  while (!stop.stopped())
  {
    bool resync_needed = false;
    if (settings_.streaming && !streaming_refused_)
    {
      followStream(stop, resync_needed);
    }
    else
    {
      pollOnce(resync_needed);
      if (!resync_needed && stop.waitFor(settings_.poll_period))
        return;
    }
    if (resync_needed && !stop.stopped())
    {
      withStats([](FollowerStats& s) { ++s.resyncs; });
      resync();
    }
  }
}
}  // namespace cnc_bridge::mtconnect
