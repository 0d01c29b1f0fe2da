// Follows one MTConnect agent with sequence continuity: /probe once per agent instance, /current,
// then /sample?from=<next>&interval=... (the multipart stream; polling /sample when the agent
// refuses to stream). A gap (the agent's buffer overran: firstSequence beyond what was asked, or
// an OUT_OF_RANGE answer) and an agent restart (a new instanceId) are counted, reported and
// recovered from with a fresh /current.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>
#include <vector>

#include "cnc_bridge/mtconnect/documents.h"
#include "cnc_bridge/mtconnect/http.h"
#include "cnc_bridge/transport/backoff.h"

namespace cnc_bridge::mtconnect
{
struct FollowerSettings
{
  std::string device;                  ///< device name or uuid; empty: the agent's first device
  Milliseconds interval{100};          ///< the stream's interval (agent-side batching)
  Milliseconds heartbeat{1000};        ///< the stream's heartbeat when nothing changes
  unsigned count = 1000;               ///< observations per document at most
  bool streaming = true;               ///< false: poll /sample
  Milliseconds poll_period{500};       ///< between polls
  Milliseconds request_timeout{5000};  ///< an answer (or, streaming, a heartbeat) must come within
};

/// \brief Counters and the last events, for diagnostics.
struct FollowerStats
{
  std::string instance_id;
  std::string agent_version;
  uint64_t next_sequence = 0;
  uint64_t documents = 0;
  uint64_t observations = 0;
  uint64_t gaps = 0;               ///< buffer overruns seen
  uint64_t lost_observations = 0;  ///< sequence numbers skipped by those gaps (as far as known)
  uint64_t restarts = 0;           ///< instanceId changes seen
  uint64_t resyncs = 0;            ///< fresh /current after a gap or a restart
  uint64_t streams = 0;            ///< streaming requests made
  uint64_t polls = 0;              ///< polling /sample requests made
  bool streaming = false;          ///< following a stream now (false: polling or not connected)
  std::string last_gap;            ///< what the last gap was, in words
  std::string last_restart;
};

/// \brief What the follower found, called on the follower's thread.
class FollowerListener
{
 public:
  virtual ~FollowerListener() = default;
  /// The probe of a (new) agent instance, and the device followed.
  virtual void onProbe(const Document& probe, const Device& device) = 0;
  /// Observations of the device, in sequence order; \p snapshot: from /current (the whole state,
  /// after a connection, a gap or a restart) rather than changes.
  virtual void onObservations(const std::vector<Observation>& observations, bool snapshot) = 0;
  /// A gap or a restart, in words (also counted in the stats).
  virtual void onDiscontinuity(const std::string& what) {}
};

/// \brief Follows one agent. run() on one thread; stats() and stop() from any.
class Follower
{
 public:
  Follower(FollowerSettings settings, HttpClient& http, FollowerListener& listener);

  /// \brief Probes the agent (a new connection begins here). \throws as HttpClient, ProtocolError
  /// for an answer that is not a probe, ConfigError when the device is not there.
  void probe();
  /// \brief Follows the agent until \p stop is set (returns) or the link fails (throws).
  void follow(StopSignal& stop);

  FollowerStats stats() const;

  /// Request targets, for tests and logs.
  std::string probeTarget() const;
  std::string currentTarget() const;
  std::string sampleTarget(uint64_t from, bool streaming) const;

 private:
  enum class Verdict
  {
    kContinue,
    kResync
  };
  void resync();
  Verdict handle(const std::string& body, const char* what);
  Verdict handleStreams(const Document& doc);
  void gap(uint64_t lost, const std::string& what);
  Document fetch(const std::string& target, const char* what);
  void followStream(StopSignal& stop, bool& resync_needed);
  void pollOnce(bool& resync_needed);
  template <class F>
  void withStats(F f)
  {
    std::lock_guard<std::mutex> lock(mutex_);
    f(stats_);
  }

  FollowerSettings settings_;
  HttpClient& http_;
  FollowerListener& listener_;
  std::string device_name_;  ///< the followed device's name, as DeviceStream elements name it
  std::string instance_;     ///< instanceId the sequence numbers belong to
  uint64_t next_ = 0;        ///< next sequence wanted
  bool streaming_refused_ = false;
  mutable std::mutex mutex_;
  FollowerStats stats_;
};
}  // namespace cnc_bridge::mtconnect
