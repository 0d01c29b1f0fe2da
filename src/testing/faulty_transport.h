// A Transport decorator that damages traffic the way a noisy RS-232 line does: flipped bits,
// dropped and doubled bytes, whole writes lost (a lost ACK). Reproducible: the same start value of
// its random generator damages the same bytes, so a failing transfer can be replayed. Used by the
// fault-injection tests and by sim_haas_serial --faults.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <random>
#include <string>

#include "cnc_bridge/transport/forwarding_transport.h"

namespace cnc_bridge
{
/// \brief Probabilities of each fault (0..1) and the random generator's start value.
struct FaultSettings
{
  double flip = 0.0;        ///< per byte: XOR with a random non-zero mask
  double drop = 0.0;        ///< per byte: the byte is lost
  double duplicate = 0.0;   ///< per byte: the byte arrives twice
  double lose_write = 0.0;  ///< per write: everything in it is lost (a lost ACK or a lost packet)
  bool on_read = false;     ///< damage bytes read as well as bytes written
  uint32_t seed = 1;        ///< start value of the random generator (key "seed")

  /// \brief Parses "flip=0.001,drop=0.001,dup=0.0005,lose=0.01,read=1,seed=7" (any subset).
  /// \throws ConfigError on an unknown key or a value out of range.
  static FaultSettings parse(const std::string& text);
  bool any() const { return flip > 0 || drop > 0 || duplicate > 0 || lose_write > 0; }
};

/// \brief Counts of the faults injected so far.
struct FaultCounts
{
  uint64_t flipped = 0;
  uint64_t dropped = 0;
  uint64_t duplicated = 0;
  uint64_t lost_writes = 0;
};

/// \brief Damages the bytes passing through \p inner. Thread-safe as the inner transport is; the
/// random generator is guarded so a reader and a writer thread may share one object.
class FaultyTransport : public ForwardingTransport
{
 public:
  /// \param inner must outlive this object.
  FaultyTransport(Transport& inner, FaultSettings settings);

  using ForwardingTransport::write;
  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override;
  void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override;
  std::string describe() const override { return inner_.describe() + " (with injected faults)"; }

  FaultCounts counts() const;

 private:
  /// Applies per-byte faults to \p in, appending the damaged bytes to \p out.
  void damage(const uint8_t* in, size_t size, std::string& out);

  FaultSettings settings_;
  mutable std::mutex mutex_;
  std::mt19937 random_;
  FaultCounts counts_;
};
}  // namespace cnc_bridge
