#include "client/net/stream_client.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <boost/asio.hpp>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <thread>
#include <unordered_set>
#include <utility>  // before Boost.Asio, whose awaitable.hpp uses std::exchange

#include "common/core/error.h"
#include "common/core/ivec_less.h"
#include "protocol/geometry/byte_coding.h"
#include "protocol/geometry/geometry_codec.h"
#include "protocol/impostor/impostor_codec.h"
#include "protocol/impostor/impostor_message.h"
#include "protocol/wire/peer.h"

namespace vistream {

namespace asio = boost::asio;
using asio::ip::tcp;
using namespace vistream::wire;

namespace {
struct HeldFace {
  uint16_t material = 0;
  std::vector<glm::vec3> corners;
  std::vector<uint8_t> levels;       // per triangle, when the server sent lighting
  std::vector<glm::u8vec3> colours;  // the grids, one after another
};
}  // namespace

// The connection is a wire::Peer (protocol/wire/peer.h): its read loop,
// outbox and Welcome checks are the load tester's too. The Peer holds the
// Impl weakly; StreamClient joins the io thread before the Impl goes, and
// drains the handlers left (drain()), so none outlives the io_context.
struct StreamClient::Impl : PeerHandler {
  static constexpr PeerOptions kPeerOptions{.maxFrameBytes = 64u << 20};

  asio::io_context io;
  Peer::Strand strand = asio::make_strand(io);
  // The connection; replaced (under `mutex`) when it is made again.
  std::shared_ptr<Peer> peer = Peer::create(strand, kPeerOptions);
  std::weak_ptr<Impl> self;
  std::thread thread;

  // Reconnection (see StreamClientOptions); the Hello's settings.
  StreamClientOptions options;
  tcp::resolver::results_type endpoints;
  std::string sceneId;
  bool reconnectingNow = false;
  uint64_t reconnectCount = 0, bytesBefore = 0;
  std::chrono::steady_clock::time_point lostAt;
  std::chrono::milliseconds backoff{100};
  asio::steady_timer retryTimer{strand};
  std::shared_ptr<Peer> connecting;  // a reconnection's socket until it connects
  std::vector<uint8_t> lastPose;     // sent again after reconnecting

  mutable std::mutex mutex;
  std::condition_variable changed;
  bool welcomed = false, ended = false;
  std::string endReason;
  WelcomeGrid grid;
  std::vector<glm::vec3> materials;
  glm::vec3 sky{0.55f, 0.7f, 0.9f};
  std::optional<Backdrop> backdrop;  // the baked lighting's (Welcome), if it sent one
  std::optional<float> groundY;      // local frame; an assumed ground plane (Welcome)
  std::map<uint32_t, HeldFace> faces;
  std::set<glm::ivec3, IvecLess> ready;
  glm::ivec3 poseCell{0};
  uint64_t version = 0;
  // Faces received or evicted since the last takeDelta(). Past a bound (a
  // consumer that never takes deltas) the set is dropped and the next delta
  // replaces everything.
  std::unordered_set<uint32_t> changedFaces;
  bool replaceAll = true;  // the first delta carries everything

  // Other users (Avatar updates), with when each was last reported.
  using Clock = std::chrono::steady_clock;
  struct Remote {
    vistream::AvatarState state;
    glm::vec3 velocity{0.0f};
    Clock::time_point at;
  };
  std::map<uint32_t, Remote> remotes;
  Clock::time_point lastPoseSent{};
  std::vector<AvatarModelOffer> models;
  std::vector<uint8_t> modelRequested;
  std::optional<AvatarLight> avatarLight;

  // Impostors of the last cells received, oldest first (at most
  // wire::kImpostorCellsHeld, the rule the server mirrors).
  bool impostorsOffered = false;
  size_t maxImpostorBytes = size_t(1) << 30;
  std::deque<std::shared_ptr<ImpostorSet>> impostorCells;
  size_t impostorMemory = 0;
  ImpostorFigures impostorFigures;

  // Called with `mutex` held.
  void noteChanged(uint32_t face) {
    if (replaceAll) return;
    changedFaces.insert(face);
    if (changedFaces.size() > faces.size() + 100'000) {
      changedFaces.clear();
      replaceAll = true;
    }
  }
  // Appends a held face's triangles with their colours: the lighting grids
  // the server sent, or flat from the material (called with `mutex` held).
  void appendFace(RenderGeometry& g, uint32_t id, const HeldFace& f) const {
    const size_t triangles = f.corners.size() / 3;
    const bool lit = f.levels.size() == triangles;
    const glm::vec3 diffuse =
        f.material < materials.size() ? materials[f.material] : glm::vec3(0.8f);
    size_t at = 0;
    for (size_t t = 0; t < triangles; ++t) {
      const glm::vec3* c = f.corners.data() + 3 * t;
      for (int k = 0; k < 3; ++k) {
        g.triangles.positions.push_back(c[k]);
        g.bounds.extend(c[k]);
      }
      g.triangles.faceIds.push_back(id);
      g.triangles.objectIds.push_back(0);
      g.triangles.degenerate.push_back(isDegenerateTriangle(c[0], c[1], c[2]) ? 1 : 0);
      if (lit) {
        const uint32_t n = f.levels[t];
        g.lighting.append(n, f.colours.data() + at, LightingGrid::pointsOf(n));
        at += LightingGrid::pointsOf(n);
      } else {
        g.lighting.appendFlat(shadeTriangle(c[0], c[1], c[2], diffuse));
      }
    }
  }
  // Sky, ground and haze of geometry assembled by appendFace (`mutex` held).
  void finishGeometry(RenderGeometry& g) const {
    if (backdrop) {
      setBackdrop(g, *backdrop);
    } else {
      g.sky = encodeColour(sky);
      g.haze = Haze{};
    }
    g.groundY = groundY;
  }
  size_t trianglesHeld = 0, maxTriangles = 0;

  void finish(const std::string& why) {
    std::shared_ptr<Peer> p;
    {
      std::lock_guard lock(mutex);
      if (ended) return;
      ended = true;
      endReason = why;
      p = peer;
      if (connecting) connecting->close();  // its connect ends at once
    }
    changed.notify_all();
    p->close();
    retryTimer.cancel();  // on the strand, or once the io thread has gone
  }
  std::shared_ptr<Peer> currentPeer() const {
    std::lock_guard lock(mutex);
    return peer;
  }
  void send(std::vector<uint8_t> frame) {
    std::shared_ptr<Peer> p;
    {
      std::lock_guard lock(mutex);
      // Nothing would carry it (and the post would never run), or it would
      // reach a new server before the Hello.
      if (ended || reconnectingNow) return;
      p = peer;
    }
    p->send(std::move(frame));
  }
  // Runs what is left on the io_context once its thread has gone: after
  // close() every pending operation ends at once, releasing the Peer.
  void drain() {
    currentPeer()->close();
    io.restart();
    io.run();
  }

  // The Hello; on a reconnection it names the faces held (as many as fit
  // kMaxHeldFacesBytes) and the scene they belong to (`mutex` held).
  std::vector<uint8_t> helloFrame(bool resuming) const {
    HelloT hello;
    hello.protocol_version = kProtocolVersion;
    hello.auth_token = options.token;
    hello.client_name = "vistream-client";
    hello.capabilities = std::make_unique<CapabilitiesT>();
    hello.capabilities->near_field_radius_m = options.radius;
    hello.capabilities->wants_avatars = options.wantsAvatars;
    hello.capabilities->wants_impostors = options.wantsImpostors;
    if (resuming) {
      std::vector<uint32_t> ids;
      ids.reserve(faces.size());
      for (const auto& [id, f] : faces) ids.push_back(id);  // ascending: a map
      hello.held_faces = idRangesWithin(ids, kMaxHeldFacesBytes);
      hello.held_scene_id = sceneId;
      hello.held_face_count = grid.faceCount;
    }
    return encodeMessage(std::move(hello));
  }

  // The connection ended after the Welcome: make it again, or end.
  void lost(const std::string& why) {
    bool retry = false;
    {
      std::lock_guard lock(mutex);
      if (ended) return;
      retry = options.reconnect && welcomed;
      if (retry) {
        if (!reconnectingNow) {
          reconnectingNow = true;
          lostAt = Clock::now();
          backoff = std::chrono::milliseconds(100);
          ++reconnectCount;
          ready.clear();  // the next server announces its own cells
          spdlog::warn("{}; reconnecting to {}:{}", why, options.host, options.port);
        }
      }
    }
    if (!retry) return finish(why);
    retryLater(why);
  }
  void retryLater(const std::string& why) {
    const double since = std::chrono::duration<double>(Clock::now() - lostAt).count();
    if (since > options.reconnectForS)
      return finish(fmt::format("{}; no server took the session again within {:g} s", why,
                                options.reconnectForS));
    retryTimer.expires_after(backoff);
    backoff = std::min(backoff * 2, std::chrono::milliseconds(2000));
    retryTimer.async_wait([weak = self, why](const boost::system::error_code& ec) {
      if (auto s = weak.lock(); s && !ec) s->attempt(why);
    });
  }
  void attempt(const std::string& why) {
    {
      std::lock_guard lock(mutex);
      if (ended) return;
    }
    auto next = Peer::create(strand, kPeerOptions);
    {
      std::lock_guard lock(mutex);
      connecting = next;
    }
    asio::async_connect(
        next->socket(), endpoints,
        [weak = self, next, why](const boost::system::error_code& ec, const tcp::endpoint&) {
          auto s = weak.lock();
          if (!s) return;
          {
            std::lock_guard lock(s->mutex);
            s->connecting.reset();
            if (s->ended) return next->close();
          }
          if (ec) return s->retryLater(why);
          boost::system::error_code ignored;
          next->socket().set_option(tcp::no_delay(true), ignored);
          std::vector<uint8_t> hello;
          {
            std::lock_guard lock(s->mutex);
            s->bytesBefore += s->peer->bytesReceived();
            s->peer = next;
            hello = s->helloFrame(true);
          }
          next->start(s);
          next->send(std::move(hello));
        });
  }

  void onPeerEnd(PeerEnd why, const std::string& text) override {
    switch (why) {
      case PeerEnd::ConnectionLost:
        return lost("connection closed: " + text);
      case PeerEnd::BadFrame:
        return finish("bad frame from the server: " + text);
      case PeerEnd::WriteFailed:
        return finish("write: " + text);
      case PeerEnd::OutboxFull:
        return finish("the server is not reading: " + text);
    }
  }
  void onFrame(const Envelope& e) override {
    dispatchPayload(
        e, Overloaded{
               [this](const Welcome& w) { onWelcome(w); },
               [this](const Geometry& g) { onGeometry(g); },
               [this](const Evict& evict) { onEvict(evict); },
               [this](const CellReady& r) { onCellReady(r); },
               [this](const Error& err) {
                 finish(fmt::format("the server refused: {}: {}", EnumNameErrorCode(err.code()),
                                    err.text() ? err.text()->str() : ""));
               },
               [this](const Bye&) { lost("the server said bye"); },
               [this](const Avatar& a) { onAvatar(a); },
               [this](const AvatarModelData& m) { onAvatarModel(m); },
               [this](const ImpostorData& m) { onImpostor(m); },
               [](Payload) {},  // Stats, PvsReply: not used here
           });
  }
  void onWelcome(const Welcome& w) {
    WelcomeGrid checked;
    try {
      checked = validateWelcome(w);
    } catch (const InputError& error) {
      return finish(std::string("the server's Welcome has no usable grid: ") + error.what());
    }
    std::string refusal = "the server sent a second Welcome";
    {
      std::lock_guard lock(mutex);
      if (welcomed && reconnectingNow) {
        // Another session of the same scene: what is held stays valid.
        const std::string id = w.scene_id() ? w.scene_id()->str() : "";
        reconnectingNow = false;
        if (id == sceneId && checked.faceCount == grid.faceCount) {
          spdlog::info("reconnected to {}:{} after {:.2f} s, holding {} faces", options.host,
                       options.port, std::chrono::duration<double>(Clock::now() - lostAt).count(),
                       faces.size());
          if (!lastPose.empty()) peer->send(std::vector<uint8_t>(lastPose));
          changed.notify_all();
          return;
        }
        refusal = fmt::format("reconnected to scene '{}' ({} faces), not '{}' ({} faces)", id,
                              checked.faceCount, sceneId, grid.faceCount);
      }
      if (!welcomed) {
        sceneId = w.scene_id() ? w.scene_id()->str() : "";
        grid = checked;
        if (isFinite(w.environment_colour()))
          sky = glm::clamp(fromWire(*w.environment_colour()), 0.0f, 1.0f);
        if (w.has_ground() && std::isfinite(w.ground_y())) groundY = w.ground_y();
        if (w.sky_rgb() && w.ground_rgb() && std::isfinite(w.haze_distance_m()) &&
            w.haze_distance_m() >= 0.0f) {
          Backdrop b;
          b.sky = {w.sky_rgb()->r(), w.sky_rgb()->g(), w.sky_rgb()->b()};
          b.ground = {w.ground_rgb()->r(), w.ground_rgb()->g(), w.ground_rgb()->b()};
          b.haze = Haze{glm::vec3(b.sky), w.haze_distance_m()};
          backdrop = b;
        }
        readAvatarOffers(w);
        impostorsOffered = w.impostors();
        if (w.materials())
          for (const MaterialInfo* m : *w.materials())
            materials.push_back(m && isFinite(m->diffuse())
                                    ? glm::clamp(fromWire(*m->diffuse()), 0.0f, 1.0f)
                                    : glm::vec3(0.8f));
        welcomed = true;
        changed.notify_all();
        return;
      }
    }
    finish(refusal);
  }
  // Welcome's avatar models and light (`mutex` held). A light of the wrong
  // length or with non-finite values is ignored (avatars then take the sky).
  void readAvatarOffers(const Welcome& w) {
    if (w.avatar_models())
      for (const AvatarModelInfo* m : *w.avatar_models()) {
        if (models.size() >= 1000) break;
        AvatarModelOffer o;
        if (m && m->name()) o.name = m->name()->str();
        if (m) o.bytes = m->bytes();
        if (m && std::isfinite(m->height_m()) && m->height_m() > 0.05f && m->height_m() < 20.0f)
          o.heightM = m->height_m();
        models.push_back(std::move(o));
      }
    modelRequested.assign(models.size(), 0);
    if (const auto* l = w.avatar_light(); l && l->size() == 100) {
      AvatarLight light;
      bool finite = true;
      for (size_t i = 0; i < 100; ++i) finite = finite && std::isfinite(l->Get(uint32_t(i)));
      if (finite) {
        for (uint32_t i = 0; i < 25; ++i)
          light.sky[i] = glm::vec3(l->Get(3 * i), l->Get(3 * i + 1), l->Get(3 * i + 2));
        for (uint32_t i = 0; i < 25; ++i) light.sun[i] = l->Get(75 + i);
        if (isFinite(w.avatar_sun_direction()) &&
            glm::length(fromWire(*w.avatar_sun_direction())) > 0.5f)
          light.sunDirection = glm::normalize(fromWire(*w.avatar_sun_direction()));
        avatarLight = light;
      }
    }
  }
  void onAvatar(const Avatar& a) {
    std::vector<uint16_t> request;
    {
      std::lock_guard lock(mutex);
      const Clock::time_point now = Clock::now();
      if (a.departed())
        for (uint32_t id : *a.departed()) remotes.erase(id);
      if (a.avatars())
        for (const wire::AvatarState* s : *a.avatars()) {
          if (!s || !isFinite(s->position()) || !std::isfinite(s->yaw_deg()) ||
              !std::isfinite(s->speed_mps()) || !std::isfinite(s->phase_s()))
            continue;  // a user we cannot place
          if (remotes.size() >= 10'000 && !remotes.count(s->session_id())) continue;
          Remote& r = remotes[s->session_id()];
          const glm::vec3 p(fromWire(*s->position()));
          const double dt = std::chrono::duration<double>(now - r.at).count();
          r.velocity = r.at != Clock::time_point{} && dt > 0.05 && dt < 2.0
                           ? (p - r.state.eye) / float(dt)
                           : glm::vec3(0.0f);
          if (!(glm::length(r.velocity) < 50.0f)) r.velocity = glm::vec3(0.0f);
          r.at = now;
          r.state.id = s->session_id();
          r.state.eye = p;
          r.state.yawDeg = s->yaw_deg();
          r.state.speed = s->speed_mps();
          r.state.phase = s->phase_s();
          r.state.model = s->model();
          if (s->model() < models.size() && !modelRequested[s->model()]) {
            modelRequested[s->model()] = 1;
            request.push_back(s->model());
          }
        }
    }
    for (uint16_t m : request) {
      AvatarModelRequestT r;
      r.model = m;
      send(encodeMessage(std::move(r)));
    }
  }
  void onAvatarModel(const AvatarModelData& m) {
    std::lock_guard lock(mutex);
    if (m.model() >= models.size() || !modelRequested[m.model()] || models[m.model()].glb)
      return;  // not asked for: ignored
    const auto* glb = m.glb();
    if (!glb || glb->size() != models[m.model()].bytes) {
      spdlog::warn("avatar model {}: {} bytes arrived, {} announced; not drawn", m.model(),
                   glb ? glb->size() : 0, models[m.model()].bytes);
      return;
    }
    models[m.model()].glb = std::make_shared<const std::string>(
        reinterpret_cast<const char*>(glb->data()), glb->size());
  }
  void onImpostor(const ImpostorData& wire) {
    ImpostorMessage m;
    std::string error;
    if (!readImpostorMessage(wire, grid.faceCount, m, error))  // grid: set on this strand
      return finish("bad impostor from the server: " + error);
    Impostor impostor;
    if (m.count > 0 && !decodeImpostor(m.data, impostor, error))
      return finish(fmt::format("bad impostor from the server: cell ({}, {}, {}) #{}: {}", m.cell.x,
                                m.cell.y, m.cell.z, m.index, error));
    if (glm::any(glm::greaterThanEqual(m.last(), grid.dims)) ||
        glm::any(glm::lessThan(m.cell, glm::ivec3(0))))
      return finish(fmt::format(
          "bad impostor from the server: view cell ({}, {}, {})-({}, {}, {}) outside the grid",
          m.cell.x, m.cell.y, m.cell.z, m.last().x, m.last().y, m.last().z));
    std::lock_guard lock(mutex);
    if (!impostorsOffered) return finish("impostors from a server that did not offer them");
    const size_t wireBytes = wire.data() ? wire.data()->size() : 0;
    if (m.index == 0) {
      // A new cell (or one sent again): it replaces what is held for it.
      for (auto it = impostorCells.begin(); it != impostorCells.end(); ++it)
        if ((*it)->index == m.cell) {
          dropImpostorCell(it);
          break;
        }
      auto set = std::make_shared<ImpostorSet>();
      set->index = m.cell;
      set->indexHi = m.last();
      set->cell = Box3f(grid.gridOrigin + glm::vec3(m.cell) * grid.cellSize,
                        grid.gridOrigin + glm::vec3(m.last() + 1) * grid.cellSize);
      set->why = m.why;
      set->expected = m.count;
      impostorCells.push_back(std::move(set));
      if (impostorCells.size() > kImpostorCellsHeld) dropImpostorCell(impostorCells.begin());
      ++impostorFigures.cells;
    } else if (impostorCells.empty() || impostorCells.back()->index != m.cell ||
               impostorCells.back()->impostors.size() != m.index) {
      return finish(fmt::format("impostor {} of cell ({}, {}, {}) out of order", m.index, m.cell.x,
                                m.cell.y, m.cell.z));
    }
    if (m.count == 0) return;
    // Copy on write: a renderer may hold the previous snapshot.
    auto next = std::make_shared<ImpostorSet>(*impostorCells.back());
    impostorMemory += impostor.bytes();
    if (impostorMemory > maxImpostorBytes)
      return finish(fmt::format("the impostors held would exceed {} bytes", maxImpostorBytes));
    next->impostors.push_back(std::make_shared<const Impostor>(std::move(impostor)));
    next->bytes += wireBytes;
    impostorCells.back() = std::move(next);
    ++impostorFigures.impostors;
    impostorFigures.bytes += wireBytes;
  }
  // Called with `mutex` held.
  void dropImpostorCell(std::deque<std::shared_ptr<ImpostorSet>>::iterator it) {
    for (const auto& i : (*it)->impostors) impostorMemory -= i->bytes();
    impostorCells.erase(it);
  }
  void onGeometry(const Geometry& geometry) {
    DecodedGeometry g;
    std::string error;
    if (!decodeGeometry(geometry, grid.quantization, g, error))  // grid: set on this strand
      return finish("bad geometry from the server: " + error);
    for (const glm::vec3& p : g.positions)
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        return finish("the server sent geometry with non-finite positions");
    bool tooMuch = false;
    {
      std::lock_guard lock(mutex);
      size_t index = 0, triangle = 0, colour = 0;
      for (size_t f = 0; f < g.faces.size(); ++f) {
        HeldFace& h = faces[g.faces[f]];
        noteChanged(g.faces[f]);
        trianglesHeld -= h.corners.size() / 3;
        h.material = g.materials[f];
        h.corners.clear();
        h.levels.clear();
        h.colours.clear();
        for (uint16_t t = 0; t < g.triangleCounts[f]; ++t, index += 3) {
          for (int k = 0; k < 3; ++k)
            h.corners.push_back(g.positions[g.indices[index + size_t(k)]]);
          if (!g.levels.empty()) {  // one level a triangle, grids in order (decodeGeometry)
            const uint32_t n = g.levels[triangle++];
            h.levels.push_back(uint8_t(n));
            h.colours.insert(h.colours.end(), g.colours.begin() + ptrdiff_t(colour),
                             g.colours.begin() + ptrdiff_t(colour + LightingGrid::pointsOf(n)));
            colour += LightingGrid::pointsOf(n);
          }
        }
        trianglesHeld += h.corners.size() / 3;
      }
      tooMuch = trianglesHeld > maxTriangles;
      ++version;
    }
    if (tooMuch) return finish(fmt::format("the server sent more than {} triangles", maxTriangles));
    changed.notify_all();
  }
  void onEvict(const Evict& evict) {
    std::lock_guard lock(mutex);
    if (const auto* ids = evict.face_ids())
      for (uint32_t f : *ids)
        if (auto it = faces.find(f); it != faces.end()) {
          trianglesHeld -= it->second.corners.size() / 3;
          faces.erase(it);
          noteChanged(f);
        }
    ready.clear();  // the server announces complete cells again
    ++version;
  }
  void onCellReady(const CellReady& r) {
    const std::vector<glm::ivec3> cells = readyCells(r);
    if (cells.empty()) return;
    std::lock_guard lock(mutex);
    ready.insert(cells.begin(), cells.end());
    changed.notify_all();
  }
};

StreamClient::StreamClient(const StreamClientOptions& o) : impl_(std::make_shared<Impl>()) {
  Impl& s = *impl_;
  s.self = impl_;
  s.options = o;
  s.maxTriangles = o.maxTriangles;
  const std::string where = fmt::format("{}:{}", o.host, o.port);
  tcp::resolver::results_type endpoints;
  try {
    tcp::resolver resolver(s.io);
    endpoints = resolver.resolve(o.host, std::to_string(o.port));
  } catch (const boost::system::system_error& e) {
    throwInputError(InputErrorCode::Unreachable, "cannot resolve {}: {}", where,
                    e.code().message());
  }
  // Connect with a deadline: an unreachable host must not hang the client.
  boost::system::error_code connectError = asio::error::timed_out;
  bool connected = false;
  asio::async_connect(s.peer->socket(), endpoints,
                      [&](const boost::system::error_code& ec, const tcp::endpoint&) {
                        connectError = ec;
                        connected = !ec;
                      });
  s.io.run_for(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(o.timeoutS)));
  if (!connected) {
    s.drain();
    throwInputError(
        InputErrorCode::Unreachable, "cannot connect to {}: {}", where,
        connectError == asio::error::timed_out || connectError == asio::error::operation_aborted
            ? fmt::format("no answer within {:.0f} s", o.timeoutS)
            : connectError.message());
  }
  s.io.restart();
  boost::system::error_code ignored;
  s.peer->socket().set_option(tcp::no_delay(true), ignored);
  s.endpoints = endpoints;
  s.maxImpostorBytes = o.maxImpostorBytes;
  s.peer->start(impl_);
  s.send(s.helloFrame(false));
  // The io thread never owns the Impl: the StreamClient joins it first.
  s.thread = std::thread([&io = s.io] { io.run(); });
  std::unique_lock lock(s.mutex);
  const bool answered = s.changed.wait_for(lock, std::chrono::duration<double>(o.timeoutS),
                                           [&] { return s.welcomed || s.ended; });
  if (!answered || !s.welcomed) {
    const std::string why =
        answered ? s.endReason : fmt::format("no Welcome within {:.0f} s", o.timeoutS);
    lock.unlock();
    s.io.stop();  // the io thread must not touch the peer while finish() closes it
    s.thread.join();
    s.finish(why);
    s.drain();
    throwInputError(InputErrorCode::Unreachable, "{}: {}", where, why);
  }
}

StreamClient::~StreamClient() {
  if (!impl_) return;
  impl_->send(encodeBye("client closed"));
  asio::post(impl_->strand, [self = impl_.get()] {
    // Let the Bye leave, then close.
    auto timer = std::make_shared<asio::steady_timer>(self->strand, std::chrono::milliseconds(100));
    timer->async_wait([self, timer](const boost::system::error_code&) { self->finish("closed"); });
  });
  if (impl_->thread.joinable()) impl_->thread.join();
  impl_->drain();
}

glm::dvec3 StreamClient::origin() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->grid.localOrigin;
}

float StreamClient::radius() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->grid.radius;
}

void StreamClient::sendPose(const glm::vec3& eye, float yawDeg, float pitchDeg,
                            const glm::vec3& velocity) {
  {
    // At most kMaxPosesPerSecond within one view cell: a headless walk
    // renders hundreds of frames a second, and the server refuses a flood
    // (a new cell always goes out, so waitForCell never waits on a dropped pose).
    std::lock_guard lock(impl_->mutex);
    const glm::ivec3 cell = impl_->grid.cellOf(eye);
    const auto now = Impl::Clock::now();
    if (cell == impl_->poseCell && impl_->lastPoseSent != Impl::Clock::time_point{} &&
        now - impl_->lastPoseSent < std::chrono::duration<double>(1.0 / kMaxPosesPerSecond))
      return;
    impl_->poseCell = cell;
    impl_->lastPoseSent = now;
  }
  PoseT pose;
  pose.position = std::make_unique<Vec3d>(toWire(glm::dvec3(eye)));
  pose.yaw_deg = yawDeg;
  pose.pitch_deg = pitchDeg;
  pose.velocity = std::make_unique<Vec3f>(toWire(velocity));
  std::vector<uint8_t> frame = encodeMessage(std::move(pose));
  {
    std::lock_guard lock(impl_->mutex);
    impl_->lastPose = frame;
  }
  impl_->send(std::move(frame));
}

bool StreamClient::waitForCell(double timeoutS) {
  std::unique_lock lock(impl_->mutex);
  return impl_->changed.wait_for(lock, std::chrono::duration<double>(timeoutS), [&] {
    return impl_->ended || impl_->ready.count(impl_->poseCell) > 0;
  }) && !impl_->ended;
}

RenderGeometry StreamClient::snapshot() const {
  std::lock_guard lock(impl_->mutex);
  RenderGeometry g;
  for (const auto& [id, f] : impl_->faces) impl_->appendFace(g, id, f);
  impl_->finishGeometry(g);
  return g;
}

GeometryDelta StreamClient::takeDelta() {
  Impl& s = *impl_;
  std::lock_guard lock(s.mutex);
  GeometryDelta d;
  d.replaceAll = s.replaceAll;
  if (s.replaceAll) {
    for (const auto& [id, f] : s.faces) s.appendFace(d.added, id, f);
  } else {
    d.removed.assign(s.changedFaces.begin(), s.changedFaces.end());
    std::sort(d.removed.begin(), d.removed.end());
    for (const uint32_t id : d.removed)
      if (const auto it = s.faces.find(id); it != s.faces.end())
        s.appendFace(d.added, id, it->second);
  }
  s.finishGeometry(d.added);
  s.changedFaces.clear();
  s.replaceAll = false;
  d.version = s.version;
  return d;
}

uint64_t StreamClient::version() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->version;
}

uint64_t StreamClient::bytesReceived() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->bytesBefore + impl_->peer->bytesReceived();
}

uint64_t StreamClient::reconnects() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->reconnectCount;
}

bool StreamClient::reconnecting() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->reconnectingNow;
}

size_t StreamClient::facesHeld() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->faces.size();
}

std::vector<vistream::AvatarState> StreamClient::avatars() const {
  std::lock_guard lock(impl_->mutex);
  const auto now = Impl::Clock::now();
  std::vector<vistream::AvatarState> out;
  for (const auto& [id, r] : impl_->remotes) {
    const float age = float(std::chrono::duration<double>(now - r.at).count());
    vistream::AvatarState s = r.state;
    s.eye += r.velocity * std::min(age, 0.6f);
    s.phase += age;
    out.push_back(s);
  }
  return out;
}

std::vector<AvatarModelOffer> StreamClient::avatarModels() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->models;
}

std::optional<AvatarLight> StreamClient::avatarLight() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->avatarLight;
}

bool StreamClient::impostorsOffered() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->impostorsOffered;
}

std::shared_ptr<const ImpostorSet> StreamClient::impostorsAt(const glm::vec3& eye) const {
  std::lock_guard lock(impl_->mutex);
  if (!impl_->welcomed) return nullptr;
  const glm::ivec3 cell = impl_->grid.cellOf(eye);
  for (const auto& set : impl_->impostorCells)
    if (set->holds(cell)) return set;
  return nullptr;
}

StreamClient::ImpostorFigures StreamClient::impostorFigures() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->impostorFigures;
}

std::string StreamClient::error() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->endReason;
}

}  // namespace vistream
