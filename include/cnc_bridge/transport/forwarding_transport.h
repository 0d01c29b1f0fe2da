// The base of Transport decorators (pacing, fault injection, push-back, counting): every call goes
// to the wrapped transport unless the decorator overrides it, so each one spells out only what it
// changes.
#pragma once

#include <string>

#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
/// \brief Forwards every Transport call to \p inner. Thread-safe as the inner transport is.
class ForwardingTransport : public Transport
{
 public:
  /// \param inner must outlive this object.
  explicit ForwardingTransport(Transport& inner) : inner_(inner) {}

  using Transport::write;
  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override
  {
    return inner_.read(buffer, size, timeout);
  }
  void write(const uint8_t* data, size_t size, Milliseconds timeout = kWaitForever) override
  {
    inner_.write(data, size, timeout);
  }
  void drain() override { inner_.drain(); }
  size_t pendingOutput() const override { return inner_.pendingOutput(); }
  void discardInput() override { inner_.discardInput(); }
  void interrupt() override { inner_.interrupt(); }
  void close() override { inner_.close(); }
  bool isOpen() const override { return inner_.isOpen(); }
  std::string describe() const override { return inner_.describe(); }

 protected:
  Transport& inner_;
};
}  // namespace cnc_bridge
