#include "server/stream/http_endpoint.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <charconv>
#include <cmath>
#include <nlohmann/json.hpp>
#include <optional>

#include "common/core/error.h"
#include "server/stream/stream_server.h"

namespace vistream {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = asio::ip::tcp;
using nlohmann::json;

constexpr auto kRequestDeadline = std::chrono::seconds(10);
constexpr size_t kHeaderLimit = 8 * 1024;
constexpr size_t kBodyLimit = 1024;  // GET requests carry none

// "%2C" and friends in a query value.
std::string percentDecoded(std::string_view text) {
  std::string out;
  for (size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '%' && i + 2 < text.size()) {
      int v = 0;
      const auto r = std::from_chars(text.data() + i + 1, text.data() + i + 3, v, 16);
      if (r.ec == std::errc() && r.ptr == text.data() + i + 3) {
        out.push_back(char(v));
        i += 2;
        continue;
      }
    }
    out.push_back(text[i] == '+' ? ' ' : text[i]);
  }
  return out;
}

// The value of `key` in a query string "a=1&b=2", if present.
std::optional<std::string> queryValue(std::string_view query, std::string_view key) {
  while (!query.empty()) {
    const size_t amp = query.find('&');
    const std::string_view pair = query.substr(0, amp);
    const size_t eq = pair.find('=');
    if (pair.substr(0, eq) == key)
      return percentDecoded(eq == std::string_view::npos ? "" : pair.substr(eq + 1));
    if (amp == std::string_view::npos) break;
    query.remove_prefix(amp + 1);
  }
  return std::nullopt;
}

// Three comma-separated finite numbers, or nothing.
std::optional<glm::dvec3> threeNumbers(const std::string& text) {
  glm::dvec3 v;
  size_t pos = 0;
  for (int k = 0; k < 3; ++k) {
    const size_t end = k < 2 ? text.find(',', pos) : text.size();
    if (end == std::string::npos) return std::nullopt;
    const char* first = text.data() + pos;
    const char* last = text.data() + end;
    const auto r = std::from_chars(first, last, v[k]);
    if (r.ec != std::errc() || r.ptr != last || !std::isfinite(v[k])) return std::nullopt;
    pos = end + 1;
  }
  return v;
}

// One HTTP connection: read a request, answer it, read the next (keep-alive).
class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(HttpEndpoint& endpoint, StreamServer& server, tcp::socket socket)
      : endpoint_(endpoint), server_(server), stream_(std::move(socket)) {}

  void start() {
    asio::dispatch(stream_.get_executor(), [self = shared_from_this()] { self->read(); });
  }

 private:
  void read() {
    parser_.emplace();
    parser_->header_limit(kHeaderLimit);
    parser_->body_limit(kBodyLimit);
    stream_.expires_after(kRequestDeadline);
    http::async_read(
        stream_, buffer_, *parser_,
        [self = shared_from_this()](beast::error_code ec, size_t) { self->onRead(ec); });
  }

  void onRead(beast::error_code ec) {
    if (ec == http::error::end_of_stream) return close();
    if (ec) {
      // A request too large or malformed gets its status; a stalled or
      // closed connection is just closed.
      if (ec.category() == http::make_error_code(http::error::bad_method).category())
        return answer(http::status::bad_request, "text/plain",
                      fmt::format("bad request: {}\n", ec.message()), /*keepAlive=*/false);
      return close();
    }
    const auto& req = parser_->get();
    const bool keepAlive = req.keep_alive();
    if (req.method() != http::verb::get)
      return answer(http::status::method_not_allowed, "text/plain", "only GET is served\n",
                    keepAlive);
    const std::string_view target(req.target().data(), req.target().size());
    const size_t q = target.find('?');
    const std::string_view path = target.substr(0, q);
    const std::string_view query = q == std::string_view::npos ? "" : target.substr(q + 1);
    if (path == "/healthz") {
      if (server_.stopping())
        return answer(http::status::service_unavailable, "text/plain", "stopping\n", false);
      return answer(http::status::ok, "text/plain", "ok\n", keepAlive);
    }
    if (path == "/metrics")
      return answer(http::status::ok, "text/plain; version=0.0.4", endpoint_.metricsText(),
                    keepAlive);
    if (path == "/pvs") return pvs(query, keepAlive);
    answer(http::status::not_found, "text/plain",
           fmt::format("no such path: {} (try /healthz, /metrics, /pvs)\n", path), keepAlive);
  }

  void pvs(std::string_view query, bool keepAlive) {
    StreamWorld& world = server_.world();
    const ViewCellGrid& grid = world.grid();
    const std::optional<std::string> point = queryValue(query, "point");
    const std::optional<std::string> cellText = queryValue(query, "cell");
    auto bad = [&](std::string text) {
      answerError(http::status::bad_request, std::move(text), keepAlive);
    };
    if (point.has_value() == cellText.has_value())
      return bad("give exactly one of point=x,y,z (file coordinates) or cell=i,j,k");
    glm::ivec3 cell{0};
    if (point) {
      const std::optional<glm::dvec3> p = threeNumbers(*point);
      if (!p) return bad(fmt::format("point: expected x,y,z, got '{}'", *point));
      const std::optional<glm::ivec3> c = grid.cellOf(world.scene().toLocal(*p));
      if (!c)
        return answerError(http::status::not_found,
                           fmt::format("point {} lies outside the view-cell grid", *point),
                           keepAlive);
      cell = *c;
    } else {
      const std::optional<glm::dvec3> c = threeNumbers(*cellText);
      if (!c || *c != glm::floor(*c) || glm::any(glm::greaterThan(glm::abs(*c), glm::dvec3(1e9))))
        return bad(fmt::format("cell: expected three integers i,j,k, got '{}'", *cellText));
      cell = glm::ivec3(*c);
      if (!grid.contains(cell))
        return answerError(http::status::not_found,
                           fmt::format("cell {} is outside the grid of {}x{}x{} cells", *cellText,
                                       grid.dims().x, grid.dims().y, grid.dims().z),
                           keepAlive);
    }
    // The PVS on the workers; the answer on this connection's strand.
    stream_.expires_never();
    world.pvs(
        cell, server_.workers(), [self = shared_from_this(), cell, keepAlive](FaceListPtr faces) {
          asio::post(self->stream_.get_executor(),
                     [self, cell, keepAlive, faces] { self->answerPvs(cell, faces, keepAlive); });
        });
  }

  void answerPvs(const glm::ivec3& cell, const FaceListPtr& faces, bool keepAlive) {
    if (!faces)
      return answerError(http::status::internal_server_error,
                         "the PVS could not be computed (see the server's log)", keepAlive);
    const StreamWorld& world = server_.world();
    const Box3f box = world.grid().cellBox(cell);
    // File coordinates to the millimetre (the local frame's float rounding
    // is noise to a reader).
    auto mm = [](double v) { return std::round(v * 1000.0) / 1000.0; };
    const glm::dvec3 lo = world.scene().toFile(box.lo), hi = world.scene().toFile(box.hi);
    answer(http::status::ok, "application/json",
           json{{"cell", {cell.x, cell.y, cell.z}},
                {"box", {mm(lo.x), mm(lo.y), mm(lo.z), mm(hi.x), mm(hi.y), mm(hi.z)}},
                {"count", faces->size()},
                {"faces", *faces}}
                   .dump() +
               "\n",
           keepAlive);
  }

  // A JSON error: {"error": text}.
  void answerError(http::status status, std::string text, bool keepAlive) {
    answer(status, "application/json", json{{"error", std::move(text)}}.dump() + "\n", keepAlive);
  }

  void answer(http::status status, const char* type, std::string body, bool keepAlive) {
    auto res = std::make_shared<http::response<http::string_body>>(status, 11);
    res->set(http::field::server, "vistream-server");
    res->set(http::field::content_type, type);
    res->keep_alive(keepAlive);
    res->body() = std::move(body);
    res->prepare_payload();
    stream_.expires_after(kRequestDeadline);
    http::async_write(stream_, *res,
                      [self = shared_from_this(), res](beast::error_code ec, size_t) {
                        if (ec || !res->keep_alive()) return self->close();
                        self->read();
                      });
  }

  void close() {
    beast::error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    stream_.close();
  }

  HttpEndpoint& endpoint_;
  StreamServer& server_;
  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
};

void counter(std::string& out, const char* name, const char* help, uint64_t value) {
  out += fmt::format("# HELP {0} {1}\n# TYPE {0} counter\n{0} {2}\n", name, help, value);
}

void gauge(std::string& out, const char* name, const char* help, double value) {
  out += fmt::format("# HELP {0} {1}\n# TYPE {0} gauge\n{0} {2}\n", name, help, value);
}

void histogram(std::string& out, const char* name, const char* help, const LatencyHistogram& h) {
  const LatencyHistogram::Snapshot s = h.snapshot();
  out += fmt::format("# HELP {0} {1}\n# TYPE {0} histogram\n", name, help);
  for (size_t b = 0; b < LatencyHistogram::kBounds.size(); ++b)
    out += fmt::format("{}_bucket{{le=\"{}\"}} {}\n", name, LatencyHistogram::kBounds[b],
                       s.cumulative[b]);
  out += fmt::format("{0}_bucket{{le=\"+Inf\"}} {1}\n{0}_sum {2}\n{0}_count {1}\n", name, s.count,
                     s.sumSeconds);
}

}  // namespace

HttpEndpoint::HttpEndpoint(StreamServer& server, const std::string& bindAddress, uint16_t port)
    : server_(server),
      bindAddress_(bindAddress),
      requestedPort_(port),
      acceptor_(asio::make_strand(server.io())) {}

HttpEndpoint::~HttpEndpoint() = default;

void HttpEndpoint::start() {
  boost::system::error_code ec;
  const auto address = asio::ip::make_address(bindAddress_, ec);
  if (ec) throwInputError("--bind {}: not an IP address", bindAddress_);
  const tcp::endpoint endpoint(address, requestedPort_);
  acceptor_.open(endpoint.protocol(), ec);
  if (!ec) acceptor_.set_option(tcp::acceptor::reuse_address(true), ec);
  if (!ec) acceptor_.bind(endpoint, ec);
  if (!ec) acceptor_.listen(asio::socket_base::max_listen_connections, ec);
  if (ec)
    throwInputError("--http-port: cannot listen on {}:{}: {}", bindAddress_, requestedPort_,
                    ec.message());
  port_ = acceptor_.local_endpoint().port();
  spdlog::info("HTTP on {}:{} (/healthz, /metrics, /pvs)", bindAddress_, port_);
  accept();
}

void HttpEndpoint::stop() {
  asio::post(acceptor_.get_executor(), [this] {
    boost::system::error_code ignored;
    acceptor_.close(ignored);
  });
}

void HttpEndpoint::accept() {
  acceptor_.async_accept(
      asio::make_strand(server_.io()), [this](boost::system::error_code ec, tcp::socket socket) {
        if (ec == asio::error::operation_aborted || !acceptor_.is_open()) return;
        if (!ec) std::make_shared<HttpSession>(*this, server_, std::move(socket))->start();
        accept();
      });
}

std::string HttpEndpoint::metricsText() const {
  std::string out;
  const StreamServer::Counters c = server_.counters();
  const StreamServer::QueueDepths q = server_.queueDepths();
  const StreamWorld& world = server_.world();
  const StreamWorld::CacheStats cs = world.cacheStats();
  const WorkQueue::Load work = world.work().load();
  gauge(out, "vistream_sessions", "Stream sessions open now.", double(q.sessions));
  counter(out, "vistream_sessions_accepted_total", "Stream sessions accepted.", c.accepted);
  counter(out, "vistream_sessions_ended_total", "Stream sessions ended.", c.ended);
  out +=
      "# HELP vistream_sessions_rejected_total Stream sessions refused at accept, by reason.\n"
      "# TYPE vistream_sessions_rejected_total counter\n";
  out += fmt::format("vistream_sessions_rejected_total{{reason=\"stopping\"}} {}\n",
                     c.rejectedStopping);
  out += fmt::format("vistream_sessions_rejected_total{{reason=\"max_clients\"}} {}\n",
                     c.rejectedFull);
  out += fmt::format("vistream_sessions_rejected_total{{reason=\"max_clients_per_address\"}} {}\n",
                     c.rejectedPerAddress);
  counter(out, "vistream_bytes_sent_total", "Bytes sent to stream clients.", c.bytesSent);
  gauge(out, "vistream_cpu_ms_per_second", "Process CPU time per wall second (ms).",
        server_.cpuMsPerSecond());
  counter(out, "vistream_pvs_cache_hits_total", "Face set and PVS cache hits.", cs.hits);
  counter(out, "vistream_pvs_cache_misses_total", "Face set and PVS cache misses.", cs.misses);
  gauge(out, "vistream_pvs_cache_hit_ratio", "Cache hits over lookups since the start.",
        cs.hits + cs.misses ? double(cs.hits) / double(cs.hits + cs.misses) : 0.0);
  counter(out, "vistream_pvs_computed_total", "PVS computations (coarse cells included).",
          cs.pvsComputed);
  counter(out, "vistream_pvs_from_database_total", "PVSs read from the database.",
          cs.pvsFromDatabase);
  counter(out, "vistream_visibility_cancelled_total",
          "Visibility computations dropped unstarted (nobody waited).", cs.cancelled);
  counter(out, "vistream_visibility_dropped_total",
          "Prefetch dropped unstarted for the queue's bound.", cs.dropped);
  gauge(out, "vistream_visibility_jobs_waiting", "Visibility jobs waiting for a worker.",
        double(work.waiting));
  gauge(out, "vistream_visibility_jobs_waiting_current",
        "Of those, current cells (a client waits for them).", double(work.waitingCurrent));
  gauge(out, "vistream_visibility_oldest_current_seconds",
        "How long the oldest waiting current cell has waited.", work.oldestCurrentS);
  gauge(out, "vistream_send_queue_bytes", "Bytes queued to stream clients, summed.",
        double(q.totalBytes));
  gauge(out, "vistream_send_queue_max_bytes", "The deepest client send queue.", double(q.maxBytes));
  histogram(out, "vistream_pvs_seconds", "From a PVS request to its answer.", world.pvsLatency());
  histogram(out, "vistream_cell_face_set_seconds",
            "From a cell face set request (a client's cell) to its answer.",
            world.faceSetLatency());
  if (const RedisPresence* presence = server_.presence()) {
    const RedisPresence::Counters pc = presence->counters();
    gauge(out, "vistream_presence_connected", "1 while both Redis connections are up.",
          pc.connected ? 1.0 : 0.0);
    gauge(out, "vistream_presence_replica", "This replica's tag (top 8 bits of session IDs).",
          double(presence->replicaTag()));
    counter(out, "vistream_presence_published_total", "Presence snapshots published.",
            pc.published);
    counter(out, "vistream_presence_received_total", "Other replicas' snapshots received.",
            pc.received);
    counter(out, "vistream_presence_malformed_total", "Presence messages dropped as malformed.",
            pc.malformed);
    counter(out, "vistream_presence_lost_total", "Times the Redis connection was lost.", pc.lost);
    gauge(out, "vistream_presence_remote_replicas", "Other replicas heard from lately.",
          double(pc.remoteReplicas));
    gauge(out, "vistream_presence_remote_users", "Users of other replicas known now.",
          double(pc.remoteUsers));
    histogram(out, "vistream_presence_seconds",
              "Presence fan-out: from another replica's publish to its receipt here.",
              presence->latency());
    out +=
        "# HELP vistream_presence_quantile_seconds Presence fan-out over the latest 4096 "
        "snapshots.\n# TYPE vistream_presence_quantile_seconds gauge\n";
    for (const double quantile : {0.5, 0.99})
      if (const std::optional<double> v = presence->latencyQuantile(quantile))
        out +=
            fmt::format("vistream_presence_quantile_seconds{{quantile=\"{}\"}} {}\n", quantile, *v);
  }
  return out;
}

}  // namespace vistream
