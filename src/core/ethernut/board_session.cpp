// ethernut_node's connection to its board (board_session.h).
#include "cnc_bridge/ethernut/board_session.h"

#include <utility>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace ethernut
{
BoardSession::BoardSession(SessionSettings settings, ClientListener* listener)
    : settings_(std::move(settings)), listener_(listener), open_(linkFactory(settings_.link))
{
  // The node's switches decide on kill, and they change at run time while one client serves a
  // whole connection: the client's own gate stays open.
  settings_.client.kill_enabled = true;
}

BoardSession::~BoardSession()
{
  stop();
}

void BoardSession::start(ReconnectingLink::StateHandler on_state)
{
  link_ = std::make_unique<ReconnectingLink>(
      "ethernut " + hardwareId(), [this] { return connect(); }, Backoff(Milliseconds(200), Milliseconds(5000)));
  link_->start([this](Transport&) { run(); }, std::move(on_state));
}

void BoardSession::stop()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  standalone_cv_.notify_all();
  if (link_)
  {
    link_->stop();
  }
}

// Opens the connection and the client on it: the client is the connection's, kept with it for
// the services and the job thread.
std::shared_ptr<Transport> BoardSession::connect()
{
  ClientOptions options;
  {
    std::unique_lock<std::mutex> lock(mutex_);
    // Standalone mode: the board dropped us on purpose; wait for a request of another mode.
    standalone_cv_.wait(lock, [&] { return !standalone_ || stopping_; });
    if (stopping_)
    {
      throw CancelledError("stopping");
    }
    options = settings_.client;
  }
  std::shared_ptr<Transport> link = open_();
  auto client = std::make_shared<Client>(*link, options, listener_);
  std::lock_guard<std::mutex> lock(mutex_);
  if (connection_.client)
  {
    addCounters(earlier_, connection_.client->stats());  // diagnostics count since the start
  }
  connection_ = Connection{link, client};
  return link;
}

void BoardSession::run()
{
  const Connection c = connection();
  c.client->run();
  bool reset = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    std::swap(reset, reset_requested_);
    if (c.client->state() == SessionState::kStandalone)
    {
      standalone_ = true;
    }
  }
  if (reset)
  {
    // The end of the session closes the connection, as the qCNC's reset does; the link comes back
    // with the backoff, and the state says why it went.
    throw LinkError("reset: the connection was closed as ~reset does (the board cleared to 0/0/0); reconnecting");
  }
}

BoardSession::Connection BoardSession::connection() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  return connection_;
}

std::shared_ptr<Client> BoardSession::client(std::string& why) const
{
  const Connection c = connection();
  if (!c.client || c.client->state() == SessionState::kDisconnected || c.client->state() == SessionState::kInitialising)
  {
    why = "not connected to the ethernut board at " + hardwareId();
    return nullptr;
  }
  return c.client;
}

std::shared_ptr<Client> BoardSession::latest() const
{
  return connection().client;
}

void BoardSession::closeAfterReset(Client& client)
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    reset_requested_ = true;
  }
  client.stop();  // the session ends and its connection closes
}

std::optional<std::string> BoardSession::selectMode(BoardMode mode)
{
  std::lock_guard<std::mutex> lock(mutex_);
  settings_.client.initial_mode = mode;  // also the mode after the next reconnection
  if (!standalone_)
  {
    return std::nullopt;
  }
  if (mode == BoardMode::kStandalone)
  {
    return std::string("already in standalone mode");
  }
  standalone_ = false;
  standalone_cv_.notify_all();
  return std::string("reconnecting in ") + toString(mode) + " mode";
}

ClientStats BoardSession::totals() const
{
  std::lock_guard<std::mutex> lock(mutex_);
  ClientStats total = earlier_;
  if (connection_.client)
  {
    addCounters(total, connection_.client->stats());
  }
  return total;
}

unsigned BoardSession::reconnects() const
{
  return link_ ? link_->reconnects() : 0u;
}
}  // namespace ethernut
}  // namespace cnc_bridge
