// MdcSession (see mdc_session.h).
#include "cnc_bridge/mdc/mdc_session.h"

#include "cnc_bridge/transport/serial_line.h"

namespace cnc_bridge
{
namespace mdc
{
MdcSession::MdcSession(const MdcSettings& settings)
    : hardware_id_(settings.link.hardwareId()), open_(linkFactory(settings.link))
{
  if (settings.link.isSerial())
  {
    port_lock_ = std::make_unique<PortLock>(settings.link.lockDevice(), settings.lock_dir);
  }
  poller_ = std::make_unique<MdcPoller>(settings.plan, settings.reply_timeout, port_lock_.get());
  // A DNC transfer on the same serial line may have set the device up its own way (the line
  // settings belong to the device, not to our open port): ours again before the next query.
  poller_->setPortRegainedHook(
      [](Transport& link)
      {
        if (auto* serial = dynamic_cast<SerialLine*>(&link))
          serial->applySettings();
      });
  if (const auto axes = settings.vars.workOffsetAxes(); !axes.empty())
  {
    poller_->setWorkOffsetAxes(axes);
  }
}

MdcSession::~MdcSession()
{
  stop();
}

void MdcSession::start(ReconnectingLink::StateHandler on_state)
{
  link_ = std::make_unique<ReconnectingLink>("haas_mdc " + hardware_id_, [this] { return open_(); });
  link_->start([this](Transport& link) { poller_->run(link, stop_); }, std::move(on_state));
}

void MdcSession::stop()
{
  stop_.stop();
  if (link_)
  {
    link_->stop();
  }
}
}  // namespace mdc
}  // namespace cnc_bridge
