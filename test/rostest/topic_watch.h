// What the C++ rostests receive from the nodes (topics, action feedback), kept in arrival order,
// and waits on it: every wait is on a condition variable notified at each arrival, with a deadline,
// never a sleep.
//   Record          a test's own fields behind one mutex, filled by its callbacks (several topics)
//   Messages<T>     values of one stream (e.g. an action's feedback), in order
//   TopicWatch<M>   Messages<M> of one topic, subscribed for as long as the watch lives
//   advertiseAndWait<M>  a publisher whose subscriber (the node) is connected
#pragma once

#include <ros/ros.h>

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace topic_watch
{
/// \brief Fields a test keeps for its callbacks (derive from it and add them), one mutex for all,
/// and waits on them. A test may hold `mutex` itself to read the fields.
struct Record
{
  std::mutex mutex;

  /// Runs \p change under the mutex, then wakes every waiter.
  template <class Change>
  void update(Change&& change)
  {
    {
      std::lock_guard<std::mutex> lock(mutex);
      change();
    }
    changed_.notify_all();
  }

  /// \returns true once \p condition (called under the mutex) holds, false after \p seconds.
  template <class Condition>
  bool waitFor(Condition&& condition, double seconds)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return changed_.wait_for(lock, std::chrono::duration<double>(seconds), [&] { return condition(); });
  }

  /// A subscription callback that appends each message to \p messages (a field of this record).
  template <class M>
  std::function<void(const boost::shared_ptr<const M>&)> appendTo(std::vector<M>& messages)
  {
    return [this, &messages](const boost::shared_ptr<const M>& message)
    { update([&] { messages.push_back(*message); }); };
  }

 private:
  std::condition_variable changed_;
};

/// \brief The values of one stream in arrival order (add() from any thread), and waits on them.
template <class T>
class Messages
{
 public:
  Messages() = default;
  Messages(const Messages&) = delete;
  Messages& operator=(const Messages&) = delete;

  void add(const T& value)
  {
    record_.update([&] { values_.push_back(value); });
  }

  /// \returns true once \p ready holds for every value received so far, false after \p seconds.
  bool waitFor(const std::function<bool(const std::vector<T>&)>& ready, double seconds = 10.0)
  {
    return record_.waitFor([&] { return ready(values_); }, seconds);
  }

  /// \returns true once the latest value satisfies \p predicate, false after \p seconds.
  bool waitForLatest(const std::function<bool(const T&)>& predicate, double seconds = 10.0)
  {
    return waitFor([&](const std::vector<T>& values) { return !values.empty() && predicate(values.back()); }, seconds);
  }

  /// The next value not yet taken by next(), or nothing if none came within \p seconds.
  std::optional<T> next(double seconds = 10.0)
  {
    std::optional<T> value;
    record_.waitFor(
        [&]
        {
          if (values_.size() > taken_)
          {
            value = values_[taken_++];
          }
          return value.has_value();
        },
        seconds);
    return value;
  }

  std::vector<T> all()
  {
    std::lock_guard<std::mutex> lock(record_.mutex);
    return values_;
  }

  size_t size()
  {
    std::lock_guard<std::mutex> lock(record_.mutex);
    return values_.size();
  }

  /// The latest value (a default-made one if none came yet).
  T latest()
  {
    std::lock_guard<std::mutex> lock(record_.mutex);
    return values_.empty() ? T() : values_.back();
  }

  /// Forgets the values received so far (and what next() took).
  void clear()
  {
    record_.update(
        [&]
        {
          values_.clear();
          taken_ = 0;
        });
  }

 private:
  Record record_;
  std::vector<T> values_;
  size_t taken_ = 0;
};

/// \brief Every message of one topic from the construction on (Messages<M>), and its connection.
template <class M>
class TopicWatch : public Messages<M>
{
 public:
  explicit TopicWatch(const std::string& topic, uint32_t queue_size = 100, ros::NodeHandle nh = ros::NodeHandle())
  {
    subscriber_ =
        nh.subscribe<M>(topic, queue_size, [this](const boost::shared_ptr<const M>& message) { this->add(*message); });
  }

  /// Publishers of the topic connected to us (a message published before the connection is lost).
  uint32_t publishers() const { return subscriber_.getNumPublishers(); }
  bool connected() const { return publishers() > 0; }

  /// \returns true once a publisher is connected, false after \p seconds. Polled every 10 ms: roscpp
  /// offers no event for a new connection.
  bool waitForPublisher(double seconds = 20.0) const
  {
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(seconds);
    while (!connected() && ros::WallTime::now() < deadline)
    {
      ros::WallDuration(0.01).sleep();  // poll: roscpp offers no wait for a connection
    }
    return connected();
  }

 private:
  ros::Subscriber subscriber_;
};

/// \brief A publisher of \p topic once a subscriber is connected (a message published before the
/// connection is lost); after \p seconds without one, the caller finds getNumSubscribers() 0.
/// Polled every 10 ms: roscpp offers no event for a new connection.
template <class M>
ros::Publisher advertiseAndWait(const std::string& topic, double seconds = 20.0, ros::NodeHandle nh = ros::NodeHandle())
{
  ros::Publisher publisher = nh.advertise<M>(topic, 10);
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(seconds);
  while (publisher.getNumSubscribers() == 0 && ros::WallTime::now() < deadline)
  {
    ros::WallDuration(0.01).sleep();  // poll: roscpp offers no wait for a subscriber
  }
  return publisher;
}
}  // namespace topic_watch
