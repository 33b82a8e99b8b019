// The NATS connection shared by the origin's publisher and the gateway, and the scene's
// subjects (nats_subjects.h).
#include "nats_link.h"

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <fstream>
#include <memory>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/service/nats_subjects.h"
#include "irradcast/wire/scene_package.h"

namespace irradcast {

NatsSubjects nats_subjects(const std::string& scene_id) {
  NatsSubjects s;
  for (char c : scene_id) {
    const bool plain = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                       c == '-' || c == '_';
    s.token += plain ? c : '_';
  }
  if (s.token.empty() || s.token != scene_id)
    s.token += "-" + wire::hex(wire::sha256(scene_id)).substr(0, 8);
  const std::string p = "irradcast." + s.token + ".";
  s.stream = "IRRADCAST_" + s.token;
  s.filter = p + "s.>";
  s.state = p + "s.state";
  s.package_prefix = p + "s.package.";
  s.tile_prefix = p + "s.tile.";
  s.edit = p + "s.edit";
  s.stats = p + "s.stats";
  s.volume = p + "s.volume";
  s.volume_prefix = p + "s.volchunk.";
  s.poses = p + "s.poses";
  s.presence = p + "s.presence";
  s.cameras = p + "req.cameras";
  s.submit = p + "req.edit";
  return s;
}

namespace nats_link {

std::string describe(natsStatus s) {
  const char* last = nats_GetLastError(nullptr);
  std::string text = natsStatus_GetText(s);
  if (last && *last && text != last) text += ": " + std::string(last);
  return text;
}

std::string data_of(natsMsg* msg) {
  const char* d = natsMsg_GetData(msg);
  const int n = natsMsg_GetDataLength(msg);
  return d && n > 0 ? std::string(d, static_cast<std::size_t>(n)) : std::string();
}

void reply(natsConnection* nc, natsMsg* msg, const google::protobuf::MessageLite& m) {
  const char* to = natsMsg_GetReply(msg);
  if (!to || !*to) return;
  const std::string bytes = m.SerializeAsString();
  natsConnection_Publish(nc, to, bytes.data(), static_cast<int>(bytes.size()));
}

struct Subscription::Gate {
  std::mutex running;  // held while the handler runs
  Handler handler;
  std::mutex mutex;
  std::condition_variable cv;
  bool watched = false, complete = false;

  static void on_message(natsConnection* nc, natsSubscription*, natsMsg* msg, void* self) {
    Gate& g = *static_cast<Gate*>(self);
    std::lock_guard lock(g.running);
    if (g.handler)
      g.handler(nc, msg);
    else
      natsMsg_Destroy(msg);
  }
  static void on_complete(void* self) {
    Gate& g = *static_cast<Gate*>(self);
    std::lock_guard lock(g.mutex);
    g.complete = true;
    g.cv.notify_all();
  }
};

namespace {
// Gates whose subscription never reported completion in time: libnats may still call them (they
// drop the message), so they stay, reachable, for the life of the process.
std::mutex parked_mutex;
std::vector<std::unique_ptr<Subscription::Gate>>& parked() {
  static std::vector<std::unique_ptr<Subscription::Gate>> gates;
  return gates;
}
}  // namespace

natsStatus Subscription::subscribe(natsConnection* nc, const std::string& subject,
                                   Handler handler) {
  close();
  gate_ = new Gate;
  gate_->handler = std::move(handler);
  return adopt(natsConnection_Subscribe(&sub_, nc, subject.c_str(), Gate::on_message, gate_));
}

natsStatus Subscription::subscribe(jsCtx* js, const std::string& filter, jsSubOptions* options,
                                   jsErrCode* error, Handler handler) {
  close();
  gate_ = new Gate;
  gate_->handler = std::move(handler);
  return adopt(
      js_Subscribe(&sub_, js, filter.c_str(), Gate::on_message, gate_, nullptr, options, error));
}

natsStatus Subscription::adopt(natsStatus s) {
  if (s != NATS_OK) {
    natsSubscription_Destroy(sub_);
    sub_ = nullptr;
    delete gate_;
    gate_ = nullptr;
    return s;
  }
  gate_->watched = natsSubscription_SetOnCompleteCB(sub_, Gate::on_complete, gate_) == NATS_OK;
  return s;
}

void Subscription::close() {
  if (!sub_) return;
  {
    std::lock_guard lock(gate_->running);  // waits for a handler that is running
    gate_->handler = nullptr;
  }
  // Removes the interest (a JetStream consumer is left to expire on the server: libnats 3.4
  // deletes it only on an explicit unsubscribe, whose error path reads freed memory while an
  // ordered consumer is being reset after a reconnection).
  natsSubscription_Destroy(sub_);
  sub_ = nullptr;
  bool complete = false;
  if (gate_->watched) {
    std::unique_lock lock(gate_->mutex);
    complete = gate_->cv.wait_for(lock, std::chrono::seconds(5), [&] { return gate_->complete; });
  }
  if (complete) {
    delete gate_;
  } else {
    log::warn("nats", "a subscription did not report its end in 5 s; its handler stays parked");
    std::lock_guard lock(parked_mutex);
    parked().emplace_back(gate_);
  }
  gate_ = nullptr;
}

namespace {
// The first line of `path`, without surrounding white space.
std::string first_line(const std::string& path, const char* flag) {
  std::ifstream f(path);
  std::string line;
  if (!f || !std::getline(f, line)) throw Error(std::string(flag) + ": cannot read '" + path + "'");
  const char* space = " \t\r\n";
  const std::size_t a = line.find_first_not_of(space);
  if (a == std::string::npos)
    throw Error(std::string(flag) + ": the first line of '" + path + "' is empty");
  return line.substr(a, line.find_last_not_of(space) + 1 - a);
}

// The credentials and TLS of `c` on `opts`.
natsStatus apply(natsOptions* opts, const std::string& url, const NatsCredentials& c) {
  natsStatus s = NATS_OK;
  if (c.tls(url)) s = natsOptions_SetSecure(opts, true);  // no TLS from the server: no connection
  if (s == NATS_OK && !c.tls_ca.empty())
    s = natsOptions_LoadCATrustedCertificates(opts, c.tls_ca.c_str());
  if (s == NATS_OK && !c.tls_cert.empty())
    s = natsOptions_LoadCertificatesChain(opts, c.tls_cert.c_str(), c.tls_key.c_str());
  if (s == NATS_OK && !c.user.empty()) {
    const std::string password = first_line(c.password_file, "--nats-password-file");
    s = natsOptions_SetUserInfo(opts, c.user.c_str(), password.c_str());
  }
  if (s == NATS_OK && !c.creds_file.empty())
    s = natsOptions_SetUserCredentialsFromFiles(opts, c.creds_file.c_str(), nullptr);
  if (s == NATS_OK && !c.nkey_file.empty()) {
    const std::string pub = nkey_public_key(first_line(c.nkey_file, "--nats-nkey"));
    s = natsOptions_SetNKeyFromSeed(opts, pub.c_str(), c.nkey_file.c_str());
  }
  return s;
}
}  // namespace

Connection::Connection(const std::string& url, const NatsCredentials& credentials,
                       const std::string& name, std::function<void()> changed)
    : shared_(new Shared{redact_nats_url(url), std::move(changed)}) {
  if (url.rfind("nats://", 0) != 0 && url.rfind("tls://", 0) != 0) {
    const std::string shown = shared_->url;
    delete shared_;
    throw Error("--nats: '" + shown + "' is not a nats:// or tls://HOST:PORT URL");
  }
  try {
    credentials.validate();
  } catch (...) {
    delete shared_;
    throw;
  }
  natsStatus s = natsOptions_Create(&opts_);
  if (s == NATS_OK) s = natsOptions_SetURL(opts_, url.c_str());
  if (s == NATS_OK) {
    try {
      s = apply(opts_, url, credentials);
    } catch (...) {
      natsOptions_Destroy(opts_);
      delete shared_;
      throw;
    }
  }
  if (s == NATS_OK) s = natsOptions_SetName(opts_, name.c_str());
  if (s == NATS_OK) s = natsOptions_SetMaxReconnect(opts_, -1);
  if (s == NATS_OK) s = natsOptions_SetReconnectWait(opts_, 250);
  if (s == NATS_OK) s = natsOptions_SetTimeout(opts_, 2000);
  if (s == NATS_OK) s = natsOptions_SetPingInterval(opts_, 5000);
  if (s == NATS_OK) s = natsOptions_SetRetryOnFailedConnect(opts_, true, on_connected, shared_);
  if (s == NATS_OK) s = natsOptions_SetReconnectedCB(opts_, on_connected, shared_);
  if (s == NATS_OK) s = natsOptions_SetDisconnectedCB(opts_, on_disconnected, shared_);
  if (s == NATS_OK) s = natsOptions_SetClosedCB(opts_, on_closed, shared_);
  if (s == NATS_OK) s = natsConnection_Connect(&nc_, opts_);
  if (s == NATS_NOT_YET_CONNECTED)
    log::warn("nats", "NATS at " + shared_->url + " is not there yet; retrying in the background");
  else if (s == NATS_OK)
    shared_->up();
  if (s == NATS_OK || s == NATS_NOT_YET_CONNECTED) s = natsConnection_JetStream(&js_, nc_, nullptr);
  if (s != NATS_OK) {
    const std::string why = describe(s);
    const std::string shown = shared_->url;
    if (nc_) {  // its closed callback drops libnats's reference to shared_
      shared_->closing = true;
      natsConnection_Close(nc_);
      natsConnection_Destroy(nc_);
      Shared::release(shared_);
    } else {
      delete shared_;
    }
    natsOptions_Destroy(opts_);
    throw Error("cannot connect to NATS at " + shown + ": " + why);
  }
}

Connection::~Connection() {
  shared_->closing = true;
  jsCtx_Destroy(js_);
  natsConnection_Close(nc_);  // the closed callback drops libnats's reference
  natsConnection_Destroy(nc_);
  Shared::release(shared_);
  natsOptions_Destroy(opts_);
}

void Connection::Shared::up() {
  if (closing || connected.exchange(true)) return;
  ++generation;
  log::info("nats", "connected to " + url);
  if (changed) changed();
}

void Connection::on_connected(natsConnection*, void* shared) {
  static_cast<Shared*>(shared)->up();
}

void Connection::on_disconnected(natsConnection*, void* shared) {
  auto* c = static_cast<Shared*>(shared);
  if (c->closing || !c->connected.exchange(false)) return;
  log::warn("nats", "lost the connection to " + c->url + "; reconnecting");
  if (c->changed) c->changed();
}

void Connection::on_closed(natsConnection* nc, void* shared) {
  auto* c = static_cast<Shared*>(shared);
  // Closed while its owner still wants it: libnats gave up (a server that does not negotiate
  // the TLS that tls:// or a TLS file requires, refused credentials): say why, once.
  const char* last = nullptr;
  if (!c->closing && natsConnection_GetLastError(nc, &last) != NATS_OK && last && *last)
    log::error("nats", "the connection to " + c->url + " is closed: " + last);
  Shared::release(c);
}

}  // namespace nats_link
}  // namespace irradcast
