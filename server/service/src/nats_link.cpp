// The NATS connection shared by the origin's publisher and the gateway, and the scene's
// subjects (nats_subjects.h).
#include "nats_link.h"

#include <cstdio>

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

Connection::Connection(const std::string& url, const std::string& name,
                       std::function<void()> changed)
    : shared_(new Shared{url, std::move(changed)}) {
  if (url.rfind("nats://", 0) != 0 && url.rfind("tls://", 0) != 0) {
    delete shared_;
    throw Error("--nats: '" + url + "' is not a nats://HOST:PORT URL");
  }
  natsStatus s = natsOptions_Create(&opts_);
  if (s == NATS_OK) s = natsOptions_SetURL(opts_, url.c_str());
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
    log::warn("nats", "NATS at " + url + " is not there yet; retrying in the background");
  else if (s == NATS_OK)
    shared_->up();
  if (s == NATS_OK || s == NATS_NOT_YET_CONNECTED) s = natsConnection_JetStream(&js_, nc_, nullptr);
  if (s != NATS_OK) {
    const std::string why = describe(s);
    if (nc_) {  // its closed callback deletes shared_
      shared_->closing = true;
      natsConnection_Close(nc_);
      natsConnection_Destroy(nc_);
    } else {
      delete shared_;
    }
    natsOptions_Destroy(opts_);
    throw Error("cannot connect to NATS at " + url + ": " + why);
  }
}

Connection::~Connection() {
  shared_->closing = true;
  jsCtx_Destroy(js_);
  natsConnection_Close(nc_);  // the closed callback deletes shared_
  natsConnection_Destroy(nc_);
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

void Connection::on_closed(natsConnection*, void* shared) {
  delete static_cast<Shared*>(shared);
}

}  // namespace nats_link
}  // namespace irradcast
