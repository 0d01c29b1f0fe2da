// ReconnectingLink (see reconnecting_link.h): the Reconnector loop around an owned Transport.
#include "cnc_bridge/transport/reconnecting_link.h"

namespace cnc_bridge
{
ReconnectingLink::ReconnectingLink(std::string name, Opener open, Backoff backoff)
    : name_(std::move(name)), open_(std::move(open)), backoff_(backoff)
{
}

ReconnectingLink::~ReconnectingLink()
{
  stop();
}

void ReconnectingLink::start(Session session, StateHandler on_state)
{
  Reconnector::Callbacks callbacks;
  callbacks.connect = [this]
  {
    {
      // Release the previous link first: a serial port must be closed before it is reopened.
      std::lock_guard<std::mutex> lock(mutex_);
      link_.reset();
    }
    std::shared_ptr<Transport> link = open_();
    std::lock_guard<std::mutex> lock(mutex_);
    link_ = std::move(link);
  };
  callbacks.session = [this, session = std::move(session)]
  {
    std::shared_ptr<Transport> link;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      link = link_;
    }
    session(*link);
  };
  callbacks.on_state = std::move(on_state);
  // After a failure and from stop() (another thread): interrupt only; the link thread replaces the
  // link on its next connect.
  callbacks.disconnect = [this] { interrupt(); };
  reconnector_ = std::make_unique<Reconnector>(name_, std::move(callbacks), backoff_);
  reconnector_->start();
}

void ReconnectingLink::stop()
{
  if (reconnector_)
  {
    reconnector_->stop();
  }
  // Dropped, not closed here: a withLink() caller may still be using it; the last owner closes it.
  std::lock_guard<std::mutex> lock(mutex_);
  link_.reset();
}

bool ReconnectingLink::withLink(const std::function<void(Transport&)>& use)
{
  std::shared_ptr<Transport> link;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    link = link_;
  }
  if (!link || !link->isOpen())
  {
    return false;
  }
  use(*link);
  return true;
}

void ReconnectingLink::interrupt()
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (link_)
  {
    link_->interrupt();
  }
}

bool ReconnectingLink::isUp() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return link_ && link_->isOpen();
}

unsigned ReconnectingLink::reconnects() const
{
  return reconnector_ ? reconnector_->reconnects() : 0;
}

unsigned ReconnectingLink::failures() const
{
  return reconnector_ ? reconnector_->failures() : 0;
}
}  // namespace cnc_bridge
