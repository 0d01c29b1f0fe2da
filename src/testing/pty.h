// Pseudo-terminals: the device side of a simulated serial link. A simulator (or a test acting as
// the machine) owns the master; the node under test opens slavePath() as if it were /dev/ttyUSB0.
#pragma once

#include <boost/asio/posix/stream_descriptor.hpp>
#include <string>

#include "cnc_bridge/transport/asio_stream.h"

namespace cnc_bridge
{
/// \brief The master side of a pty, as a Transport. Thread-safe only for interrupt().
///
/// The slave is put in raw mode and held open by this object, so the pair stays usable while the
/// peer closes and reopens the slave (as a real port stays wired when a program closes it).
class PtyMaster : public AsioStreamTransport<boost::asio::posix::stream_descriptor>
{
 public:
  /// \param link_path if not empty, a symbolic link created to the slave, its folder made if
  ///        missing (the link is removed on destruction).
  /// \throws LinkError if no pty can be allocated or the link cannot be made.
  explicit PtyMaster(const std::string& link_path = "");
  ~PtyMaster() override;

  /// \brief The device the peer opens (/dev/pts/N, or link_path when given).
  const std::string& slavePath() const { return link_path_.empty() ? slave_path_ : link_path_; }

  void drain() override;
  void discardInput() override;
  std::string describe() const override { return "pty " + slavePath(); }

 private:
  int slave_fd_ = -1;
  std::string slave_path_;
  std::string link_path_;
};
}  // namespace cnc_bridge
