// What the origin's publisher and the gateway share of the NATS C client (libnats): a
// connection that retries in the background until the server is there and reconnects forever,
// with its JetStream context and a generation that counts (re)connections; and small helpers.
#pragma once

#include <nats/nats.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>

#include <google/protobuf/message_lite.h>

#include <mutex>
#include <vector>

#include "irradcast/service/nats_credentials.h"
#include "irradcast/service/tile_source.h"

namespace irradcast::nats_link {

class Connection {
 public:
  // Starts connecting to `url` (nats:// or tls://HOST:PORT) with `credentials` (user and
  // password, credentials file or NKey; TLS required for tls:// or any TLS file); returns at once
  // when the server is not there yet (the client keeps trying). `changed` runs on a libnats
  // thread after every connect, disconnect and reconnect. Throws irradcast::Error on a bad URL or
  // options. The URL is logged only redacted (redact_nats_url).
  Connection(const std::string& url, const NatsCredentials& credentials, const std::string& name,
             std::function<void()> changed);
  ~Connection();
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  natsConnection* nc() const { return nc_; }
  jsCtx* js() const { return js_; }
  bool connected() const { return shared_->connected; }
  // Counts the times the connection was established (0: never yet).
  std::uint64_t generation() const { return shared_->generation; }
  const std::string& url() const { return shared_->url; }  // redacted

 private:
  // What libnats's callbacks see. They run on its own thread, also after the connection is
  // closed; and libnats may close the connection on its own (TLS not offered, credentials
  // refused) while the owner still reads it. So two references hold it, the owner's and
  // libnats's (dropped by the closed callback, the last one), and the last to go deletes it.
  struct Shared {
    std::string url;
    std::function<void()> changed;
    std::atomic<bool> connected{false};
    std::atomic<bool> closing{false};  // the owner is going: tell it nothing more
    std::atomic<std::uint64_t> generation{0};
    std::atomic<int> refs{2};
    void up();
    static void release(Shared* s) {
      if (s->refs.fetch_sub(1) == 1) delete s;
    }
  };
  static void on_connected(natsConnection* nc, void* shared);
  static void on_disconnected(natsConnection* nc, void* shared);
  static void on_closed(natsConnection* nc, void* shared);
  Shared* shared_;
  natsOptions* opts_ = nullptr;
  natsConnection* nc_ = nullptr;
  jsCtx* js_ = nullptr;
};

// A subscription whose handler is known to be done once it is closed. libnats calls handlers on
// its own threads and may still be inside one, or about to enter one, when
// natsSubscription_Destroy returns; freeing what the handler uses then is a use after free.
// Here the handler runs under a gate that close() shuts (waiting for a running call), and the
// gate lives until libnats reports the subscription complete.
class Subscription {
 public:
  // Owns `msg` (natsMsg_Destroy it).
  using Handler = std::function<void(natsConnection* nc, natsMsg* msg)>;
  Subscription() = default;
  ~Subscription() { close(); }
  Subscription(const Subscription&) = delete;
  Subscription& operator=(const Subscription&) = delete;

  // A core NATS subscription (closes the one held first).
  natsStatus subscribe(natsConnection* nc, const std::string& subject, Handler handler);
  // A JetStream one.
  natsStatus subscribe(jsCtx* js, const std::string& filter, jsSubOptions* options,
                       jsErrCode* error, Handler handler);
  // Unsubscribes; when it returns the handler is not running and will not run again.
  void close();
  bool active() const { return sub_ != nullptr; }

  struct Gate;  // nats_link.cpp

 private:
  natsStatus adopt(natsStatus s);
  Gate* gate_ = nullptr;
  natsSubscription* sub_ = nullptr;
};

// The Server's listeners on a TileSource that NATS feeds (set from any thread, called from the
// thread that publishes or receives).
class Listeners {
 public:
  void set(TileSource::PublishListener l) {
    std::lock_guard lock(mutex_);
    tiles_ = std::move(l);
  }
  void set(TileSource::EditListener l) {
    std::lock_guard lock(mutex_);
    edits_ = std::move(l);
  }
  // An empty list too: the probe volume changed alone (the sessions look at it in the fan-out).
  void tiles(const std::vector<std::uint32_t>& changed) {
    std::lock_guard lock(mutex_);
    if (tiles_) tiles_(changed);
  }
  void edit(const AppliedEdit& applied) {
    std::lock_guard lock(mutex_);
    if (edits_) edits_(applied);
  }

 private:
  std::mutex mutex_;
  TileSource::PublishListener tiles_;
  TileSource::EditListener edits_;
};

// "NATS_TIMEOUT: ..." for a log line or an Error.
std::string describe(natsStatus s);
// A message's bytes, or "" for none.
std::string data_of(natsMsg* msg);
// Serialises and publishes a reply (msg's reply subject); nothing when it has none.
void reply(natsConnection* nc, natsMsg* msg, const google::protobuf::MessageLite& m);

}  // namespace irradcast::nats_link
