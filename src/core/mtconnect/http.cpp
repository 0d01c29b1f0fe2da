#include "cnc_bridge/mtconnect/http.h"

#include <boost/beast/core/buffers_range.hpp>
#include <boost/beast/http/error.hpp>
#include <boost/beast/http/parser.hpp>
#include <boost/optional.hpp>
#include <cctype>
#include <limits>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge::mtconnect
{
namespace http = boost::beast::http;

namespace
{
/// A Beast Body that hands every piece of the body to a function instead of storing it, so that a
/// stream that never ends costs no memory here.
struct SinkBody
{
  using value_type = ResponseParser::BodySink;

  class reader  // NOLINT(readability-identifier-naming): the name Beast's Body concept requires
  {
   public:
    template <bool isRequest, class Fields>
    reader(http::header<isRequest, Fields>& /*header*/, value_type& sink) : sink_(sink)
    {
    }
    static void init(const boost::optional<std::uint64_t>& /*length*/, boost::beast::error_code& ec) { ec = {}; }
    template <class ConstBufferSequence>
    std::size_t put(const ConstBufferSequence& buffers, boost::beast::error_code& ec)
    {
      ec = {};
      std::size_t n = 0;
      for (const auto& b : boost::beast::buffers_range_ref(buffers))
      {
        sink_(std::string_view(static_cast<const char*>(b.data()), b.size()));
        n += b.size();
      }
      return n;
    }
    static void finish(boost::beast::error_code& ec) { ec = {}; }

   private:
    value_type& sink_;
  };
};

std::string lower(std::string_view text)
{
  std::string out(text);
  for (char& c : out)
    c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

std::string trim(std::string_view text)
{
  const auto first = text.find_first_not_of(" \t\r\n");
  if (first == std::string_view::npos)
    return "";
  const auto last = text.find_last_not_of(" \t\r\n");
  return std::string(text.substr(first, last - first + 1));
}
}  // namespace

std::string ResponseHead::multipartBoundary() const
{
  const std::string type = lower(content_type);
  if (type.rfind("multipart/", 0) != 0)
    return "";
  const auto at = type.find("boundary=");
  if (at == std::string::npos)
    return "";
  // The boundary's case matters: take it from the original text.
  std::string boundary = content_type.substr(at + 9);
  boundary = boundary.substr(0, boundary.find(';'));
  boundary = trim(boundary);
  if (boundary.size() >= 2 && boundary.front() == '"' && boundary.back() == '"')
    boundary = boundary.substr(1, boundary.size() - 2);
  return boundary;
}

struct ResponseParser::Impl
{
  BodySink sink;
  HeadSink on_head;
  http::response_parser<SinkBody> parser;
};

ResponseParser::ResponseParser(BodySink sink, const HttpLimits& limits, HeadSink on_head)
    : impl_(std::make_unique<Impl>())
{
  impl_->sink = std::move(sink);
  impl_->on_head = std::move(on_head);
  impl_->parser.get().body() = [this](std::string_view piece) { impl_->sink(piece); };
  impl_->parser.header_limit(static_cast<std::uint32_t>(limits.max_header_bytes));
  impl_->parser.body_limit(std::numeric_limits<std::uint64_t>::max());  // a stream has no end; each document is bounded
                                                                        // where it is put together
  // Not eager until the head is whole: put() then stops after the headers, so that the head
  // handler runs before the first byte of the body reaches the sink.
  impl_->parser.eager(false);
}

ResponseParser::~ResponseParser() = default;

bool ResponseParser::headDone() const
{
  return impl_->parser.is_header_done();
}
bool ResponseParser::done() const
{
  return impl_->parser.is_done();
}

void ResponseParser::feed(std::string_view data)
{
  pending_.append(data);
  pump();
}

void ResponseParser::pump()
{
  auto& parser = impl_->parser;
  while (!pending_.empty() && !parser.is_done())
  {
    boost::beast::error_code ec;
    const bool had_head = parser.is_header_done();
    const size_t used = parser.put(boost::asio::buffer(pending_.data(), pending_.size()), ec);
    pending_.erase(0, used);
    if (!had_head && parser.is_header_done())
    {
      const auto& msg = parser.get();
      head_.status = msg.result_int();
      head_.reason = std::string(msg.reason());
      head_.content_type = std::string(msg[http::field::content_type]);
      head_.keep_alive = msg.keep_alive();
      head_.chunked = parser.chunked();
      parser.eager(true);
      if (impl_->on_head)
        impl_->on_head(head_);
    }
    if (ec == http::error::need_more)
      break;
    if (ec)
    {
      throw ProtocolError("the agent's HTTP answer is malformed (" + ec.message() + ")" +
                          (parser.is_header_done() ? "" : " in its status line or headers"));
    }
    if (used == 0)
      break;
  }
}

void ResponseParser::feedEnd()
{
  if (impl_->parser.is_done())
    return;
  // Not a byte seen: Beast's parser must not be told the end (it would take the empty answer as
  // complete, or abort on its assertion).
  if (!impl_->parser.got_some())
    throw LinkError("the agent closed the connection before answering");
  boost::beast::error_code ec;
  impl_->parser.put_eof(ec);
  if (ec || !impl_->parser.is_done())
  {
    throw LinkError(impl_->parser.is_header_done() ? "the agent closed the connection in the middle of its answer"
                                                   : "the agent closed the connection before answering");
  }
}

MultipartSplitter::MultipartSplitter(std::string boundary, size_t max_part_bytes)
    : delimiter_("--" + std::move(boundary)), max_part_bytes_(max_part_bytes)
{
}

void MultipartSplitter::feed(std::string_view piece, const PartSink& sink)
{
  buffer_.append(piece);
  while (step(sink))
  {
  }
  if (buffer_.size() > max_part_bytes_ + 1024)
  {
    throw ProtocolError("a part of the agent's multipart stream exceeds " + std::to_string(max_part_bytes_) +
                        " bytes (~max_document_bytes), or its framing is broken");
  }
}

// One step of the framing; returns true when it made progress and may make more.
bool MultipartSplitter::step(const PartSink& sink)
{
  switch (state_)
  {
    case State::kBoundary:
    {
      const auto at = buffer_.find(delimiter_);
      if (at == std::string::npos)
      {
        // Keep what could be the start of a delimiter; what comes before it is CRLFs or a preamble.
        if (buffer_.size() > delimiter_.size())
          buffer_.erase(0, buffer_.size() - delimiter_.size());
        return false;
      }
      const auto eol = buffer_.find('\n', at);
      if (eol == std::string::npos)
        return false;
      buffer_.erase(0, eol + 1);
      state_ = State::kHeaders;
      content_length_ = -1;
      return true;
    }
    case State::kHeaders:
    {
      const auto eol = buffer_.find('\n');
      if (eol == std::string::npos)
        return false;
      const std::string line = trim(std::string_view(buffer_).substr(0, eol));
      buffer_.erase(0, eol + 1);
      if (line.empty())
      {
        state_ = State::kBody;
        return true;
      }
      const auto colon = line.find(':');
      if (colon != std::string::npos && lower(trim(line.substr(0, colon))) == "content-length")
      {
        const std::string value = trim(line.substr(colon + 1));
        try
        {
          size_t used = 0;
          content_length_ = std::stoll(value, &used);
          if (used != value.size() || content_length_ < 0)
            throw std::invalid_argument(value);
        }
        catch (const std::exception&)
        {
          throw ProtocolError("a part of the agent's multipart stream has Content-length '" + value + "'");
        }
        if (static_cast<unsigned long long>(content_length_) > max_part_bytes_)
        {
          throw ProtocolError("a part of the agent's multipart stream announces " + value + " bytes, more than the " +
                              std::to_string(max_part_bytes_) + " allowed (~max_document_bytes)");
        }
      }
      return true;
    }
    case State::kBody:
    {
      size_t length = 0;
      if (content_length_ >= 0)
      {
        length = static_cast<size_t>(content_length_);
        if (buffer_.size() < length)
          return false;
      }
      else
      {
        // No length: the part ends at the next delimiter, on a line of its own.
        const auto at = buffer_.find("\n" + delimiter_);
        if (at == std::string::npos)
          return false;
        length = at > 0 && buffer_[at - 1] == '\r' ? at - 1 : at;
      }
      std::string body = buffer_.substr(0, length);
      buffer_.erase(0, length);
      state_ = State::kBoundary;
      sink(std::move(body));
      return true;
    }
  }
  return false;
}

HttpClient::HttpClient(std::string host_header, Connector connect, HttpLimits limits)
    : host_(std::move(host_header)), connect_(std::move(connect)), limits_(limits)
{
}

void HttpClient::interrupt()
{
  std::lock_guard<std::mutex> lock(mutex_);
  interrupted_ = true;
  if (link_)
    link_->interrupt();
}

void HttpClient::reset()
{
  std::lock_guard<std::mutex> lock(mutex_);
  interrupted_ = false;
}

Transport& HttpClient::open()
{
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (interrupted_)
      throw CancelledError("MTConnect client stopped");
    if (link_ && link_->isOpen())
      return *link_;
  }
  std::shared_ptr<Transport> link = connect_();
  std::lock_guard<std::mutex> lock(mutex_);
  link_ = std::move(link);
  if (interrupted_)
    link_->interrupt();
  return *link_;
}

void HttpClient::release(bool keep_alive)
{
  std::lock_guard<std::mutex> lock(mutex_);
  if (!keep_alive && link_)
  {
    link_->close();
    link_.reset();
  }
}

void HttpClient::send(Transport& link, const std::string& target)
{
  link.write("GET " + target + " HTTP/1.1\r\nHost: " + host_ + "\r\nAccept: application/xml, text/xml\r\n\r\n",
             Milliseconds(5000));
}

void HttpClient::readInto(Transport& link, ResponseParser& parser, Milliseconds idle_timeout,
                          const std::function<bool()>& more)
{
  uint8_t buffer[16384];
  while (!parser.done() && more())
  {
    size_t n = 0;
    try
    {
      n = link.read(buffer, sizeof buffer, idle_timeout);
    }
    catch (const LinkError&)
    {
      parser.feedEnd();  // a whole answer ended by the close is fine; a cut one throws
      return;
    }
    if (n == 0)
    {
      throw TimeoutError("no answer from the MTConnect agent at " + link.describe() + " for " +
                         std::to_string(idle_timeout.count()) + " ms");
    }
    parser.feed(std::string_view(reinterpret_cast<const char*>(buffer), n));
  }
}

Response HttpClient::get(const std::string& target, Milliseconds idle_timeout)
{
  Transport& link = open();
  Response response;
  try
  {
    send(link, target);
    ResponseParser parser(
        [&](std::string_view piece)
        {
          if (response.body.size() + piece.size() > limits_.max_document_bytes)
          {
            throw ProtocolError("the agent's answer to " + target + " exceeds " +
                                std::to_string(limits_.max_document_bytes) + " bytes (~max_document_bytes)");
          }
          response.body.append(piece);
        },
        limits_);
    readInto(link, parser, idle_timeout, [] { return true; });
    response.head = parser.head();
    release(response.head.keep_alive);
  }
  catch (...)
  {
    release(false);
    throw;
  }
  return response;
}

HttpClient::StreamEnd HttpClient::stream(const std::string& target, Milliseconds idle_timeout,
                                         const std::function<bool(std::string&& part)>& on_part)
{
  Transport& link = open();
  StreamEnd end;
  std::unique_ptr<MultipartSplitter> splitter;
  bool wanted = true;
  try
  {
    send(link, target);
    ResponseParser parser(
        [&](std::string_view piece)
        {
          if (splitter)
          {
            splitter->feed(piece, [&](std::string&& part) { wanted = wanted && on_part(std::move(part)); });
          }
          else if (end.body.size() + piece.size() > limits_.max_document_bytes)
          {
            throw ProtocolError("the agent's answer to " + target + " exceeds " +
                                std::to_string(limits_.max_document_bytes) + " bytes (~max_document_bytes)");
          }
          else
          {
            end.body.append(piece);
          }
        },
        limits_,
        [&](const ResponseHead& head)
        {
          const std::string boundary = head.multipartBoundary();
          if (!boundary.empty() && head.status == 200)
          {
            end.multipart = true;
            splitter = std::make_unique<MultipartSplitter>(boundary, limits_.max_document_bytes);
          }
        });
    readInto(link, parser, idle_timeout, [&] { return wanted; });
    end.head = parser.head();
    // A stream is never reused: the agent writes to it until the connection goes.
    release(!end.multipart && end.head.keep_alive && parser.done());
  }
  catch (...)
  {
    release(false);
    throw;
  }
  return end;
}
}  // namespace cnc_bridge::mtconnect
