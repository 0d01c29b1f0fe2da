// The SHDR adapter's server (shdr_adapter.h): Boost.Asio, one thread; every agent's connection is
// a session with a bounded queue of lines to write and a line reader for its heartbeats.
#include "cnc_bridge/mtconnect/shdr_adapter.h"

#include <boost/asio.hpp>
#include <deque>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/log.h"

namespace cnc_bridge::mtconnect
{
namespace asio = boost::asio;
using asio::ip::tcp;

class ShdrAdapter::Impl
{
 public:
  struct Session;

  Impl(AdapterSettings settings, const std::vector<std::string>& devices);
  void start();
  void stop();
  void publish(const std::string& device, const MachineReport& report, std::chrono::system_clock::time_point when);
  AdapterStats stats() const
  {
    std::lock_guard<std::mutex> lock(mutex_);
    return stats_;
  }
  uint16_t port() const { return port_; }

 private:
  void accept();
  std::string fullState() const;  // needs mutex_
  void drop(const std::shared_ptr<Session>& session, const std::string& why);
  void closed(const std::shared_ptr<Session>& session);

  AdapterSettings settings_;
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_;
  tcp::acceptor acceptor_;
  uint16_t port_ = 0;
  std::thread thread_;
  mutable std::mutex mutex_;  // devices_, stamps_, stats_
  std::map<std::string, ShdrDevice> devices_;
  std::map<std::string, std::string> stamps_;  // device -> timestamp of its last report
  AdapterStats stats_;
  std::set<std::shared_ptr<Session>> sessions_;  // the io thread's only
  bool stopped_ = false;
};

// One agent's connection. Runs on the io thread only.
struct ShdrAdapter::Impl::Session : std::enable_shared_from_this<Session>
{
  Session(Impl& owner, tcp::socket socket)
      : owner(owner), socket(std::move(socket)), input(owner.settings_.max_line_bytes), write_timer(owner.io_)
  {
  }

  void readLine()
  {
    auto self = shared_from_this();
    asio::async_read_until(
        socket, input, '\n',
        [self](const boost::system::error_code& error, size_t n)
        {
          if (error == asio::error::not_found)
            return self->owner.drop(
                self, "sent a line longer than " + std::to_string(self->owner.settings_.max_line_bytes) + " bytes");
          if (error)
            return self->owner.closed(self);
          std::string line(asio::buffers_begin(self->input.data()),
                           asio::buffers_begin(self->input.data()) + static_cast<long>(n));
          self->input.consume(n);
          self->onLine(line);
          self->readLine();
        });
  }

  void onLine(const std::string& line)
  {
    // An agent sends only its heartbeat; anything else is ignored.
    if (line.rfind("* PING", 0) != 0)
      return;
    {
      std::lock_guard<std::mutex> lock(owner.mutex_);
      ++owner.stats_.pings;
    }
    enqueue("* PONG " + std::to_string(owner.settings_.heartbeat.count()) + "\n");
  }

  void enqueue(std::string text)
  {
    if (!socket.is_open())
      return;
    queued_bytes += text.size();
    queue.push_back(std::move(text));
    if (queued_bytes > owner.settings_.max_queued_bytes)
      return owner.drop(shared_from_this(),
                        "took too few of our lines (" + std::to_string(queued_bytes) + " bytes waiting)");
    if (!writing)
      writeNext();
  }

  void writeNext()
  {
    writing = true;
    auto self = shared_from_this();
    write_timer.expires_after(owner.settings_.write_timeout);
    write_timer.async_wait(
        [self](const boost::system::error_code& error)
        {
          if (!error)
            self->owner.drop(self,
                             "took no line for " + std::to_string(self->owner.settings_.write_timeout.count()) + " ms");
        });
    asio::async_write(socket, asio::buffer(queue.front()),
                      [self](const boost::system::error_code& error, size_t)
                      {
                        self->write_timer.cancel();
                        if (error)
                          return self->owner.closed(self);
                        self->queued_bytes -= self->queue.front().size();
                        self->queue.pop_front();
                        self->writing = false;
                        if (!self->queue.empty())
                          self->writeNext();
                      });
  }

  void close()
  {
    boost::system::error_code ignored;
    socket.shutdown(tcp::socket::shutdown_both, ignored);
    socket.close(ignored);
    write_timer.cancel();
  }

  Impl& owner;
  tcp::socket socket;
  asio::streambuf input;
  asio::steady_timer write_timer;
  std::deque<std::string> queue;
  size_t queued_bytes = 0;
  bool writing = false;
  std::string peer;
};

ShdrAdapter::Impl::Impl(AdapterSettings settings, const std::vector<std::string>& devices)
    : settings_(std::move(settings)), work_(asio::make_work_guard(io_)), acceptor_(io_)
{
  if (devices.empty())
    throw ConfigError("the SHDR adapter needs at least one device");
  for (const auto& name : devices)
  {
    if (!devices_.emplace(name, ShdrDevice(name)).second)
      throw ConfigError("device '" + name + "' is named twice");
  }
  boost::system::error_code error;
  const auto address = asio::ip::make_address(settings_.address, error);
  if (error)
    throw ConfigError("'" + settings_.address + "' is not an IP address to listen on");
  const tcp::endpoint endpoint(address, settings_.port);
  acceptor_.open(endpoint.protocol(), error);
  if (!error)
    acceptor_.set_option(tcp::acceptor::reuse_address(true), error);
  if (!error)
    acceptor_.bind(endpoint, error);
  if (!error)
    acceptor_.listen(asio::socket_base::max_listen_connections, error);
  if (error)
    throw LinkError("cannot listen for MTConnect agents on " + settings_.address + ":" +
                    std::to_string(settings_.port) + ": " + error.message() +
                    " (another adapter on that port? choose another ~port)");
  port_ = acceptor_.local_endpoint().port();
}

void ShdrAdapter::Impl::start()
{
  accept();
  thread_ = std::thread([this] { io_.run(); });
}

void ShdrAdapter::Impl::accept()
{
  acceptor_.async_accept(
      [this](const boost::system::error_code& error, tcp::socket socket)
      {
        if (error == asio::error::operation_aborted || !acceptor_.is_open())
          return;
        if (!error)
        {
          boost::system::error_code ignored;
          socket.set_option(tcp::no_delay(true), ignored);
          auto session = std::make_shared<Session>(*this, std::move(socket));
          const auto remote = session->socket.remote_endpoint(ignored);
          session->peer = remote.address().to_string() + ":" + std::to_string(remote.port());
          std::string state;
          {
            std::lock_guard<std::mutex> lock(mutex_);
            ++stats_.agents_connected;
            sessions_.insert(session);
            stats_.agents = sessions_.size();
            state = fullState();
          }
          log(LogLevel::kInfo, "mtconnect adapter: agent " + session->peer + " connected; sending the full state");
          session->enqueue(std::move(state));
          session->readLine();
        }
        accept();
      });
}

std::string ShdrAdapter::Impl::fullState() const
{
  std::string text;
  const std::string now = shdrTimestamp(std::chrono::system_clock::now());
  for (const auto& [name, device] : devices_)
  {
    const auto stamp = stamps_.find(name);
    for (const auto& line : device.fullState())
      text += shdrLine(stamp == stamps_.end() ? now : stamp->second, line);
  }
  return text;
}

void ShdrAdapter::Impl::drop(const std::shared_ptr<Session>& session, const std::string& why)
{
  if (!sessions_.count(session))
    return;
  log(LogLevel::kWarn, "mtconnect adapter: dropping agent " + session->peer + ": it " + why);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.agents_dropped;
  }
  closed(session);
}

void ShdrAdapter::Impl::closed(const std::shared_ptr<Session>& session)
{
  session->close();
  if (sessions_.erase(session) == 0)
    return;
  log(LogLevel::kInfo, "mtconnect adapter: agent " + session->peer + " disconnected");
  std::lock_guard<std::mutex> lock(mutex_);
  stats_.agents = sessions_.size();
}

void ShdrAdapter::Impl::publish(const std::string& device, const MachineReport& report,
                                std::chrono::system_clock::time_point when)
{
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = devices_.find(device);
  if (it == devices_.end())
    throw ConfigError("'" + device + "' is not a device of this adapter");
  const auto lines = it->second.update(report);
  const std::string stamp = shdrTimestamp(when);
  stamps_[device] = stamp;
  if (lines.empty())
    return;
  std::string text;
  for (const auto& line : lines)
    text += shdrLine(stamp, line);
  // Posted under the lock: the agents get the changes in the order the devices took them.
  asio::post(io_,
             [this, text = std::move(text), n = lines.size()]
             {
               for (const auto& session : std::set<std::shared_ptr<Session>>(sessions_))
                 session->enqueue(text);
               std::lock_guard<std::mutex> lock(mutex_);
               stats_.lines += n * sessions_.size();
             });
}

void ShdrAdapter::Impl::stop()
{
  if (stopped_)
    return;
  stopped_ = true;
  asio::post(io_,
             [this]
             {
               boost::system::error_code ignored;
               acceptor_.close(ignored);
               for (const auto& session : sessions_)
                 session->close();
               sessions_.clear();
               std::lock_guard<std::mutex> lock(mutex_);
               stats_.agents = 0;
             });
  work_.reset();
  if (thread_.joinable())
    thread_.join();
}

ShdrAdapter::ShdrAdapter(AdapterSettings settings, const std::vector<std::string>& devices)
    : impl_(std::make_unique<Impl>(std::move(settings), devices))
{
  impl_->start();
}

ShdrAdapter::~ShdrAdapter()
{
  impl_->stop();
}

uint16_t ShdrAdapter::port() const
{
  return impl_->port();
}

void ShdrAdapter::publish(const std::string& device, const MachineReport& report,
                          std::chrono::system_clock::time_point when)
{
  impl_->publish(device, report, when);
}

AdapterStats ShdrAdapter::stats() const
{
  return impl_->stats();
}

void ShdrAdapter::stop()
{
  impl_->stop();
}
}  // namespace cnc_bridge::mtconnect
