// The shipped NATS configuration (deploy/nats/nats.conf) against the attacks of issue 31, with a
// real nats-server on loopback: anonymous and wrong-password connections are refused; with the
// gateway's credentials nobody can read another gateway's requests, publish a tile, an edit or a
// scene state, or delete or purge the stream; with the origin's, nobody can delete it either. The
// roles still work: viewers of a gateway converge on the origin's tiles, an edit through a gateway
// applies, the admin can read the stream. The client side: credentials from files, user info in a
// URL never logged, tls:// never used in clear.
#include <gtest/gtest.h>
#include <nats/nats.h>

#include <unistd.h>
#include <cstdlib>
#include <fstream>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "cli.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/service/nats_credentials.h"
#include "irradcast/service/nats_subjects.h"
#include "irradcast_nats.pb.h"
#include "nats_fixture.h"

namespace irradcast::test_nats_security {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

const std::string kToken = "secret-token-for-nats-security";
const std::string kOriginPassword = "origin-pw-0c6e1f2a9b";
const std::string kGatewayPassword = "gateway-pw-7d3a55e0c1";
const std::string kAdminPassword = "admin-pw-91b2cc40fe";

// nats-server with deploy/nats/nats.conf (the passwords in its environment).
std::unique_ptr<test::NatsProcess> secured_nats() {
  ::setenv("IRRADCAST_NATS_ORIGIN_PASSWORD", kOriginPassword.c_str(), 1);
  ::setenv("IRRADCAST_NATS_GATEWAY_PASSWORD", kGatewayPassword.c_str(), 1);
  ::setenv("IRRADCAST_NATS_ADMIN_PASSWORD", kAdminPassword.c_str(), 1);
  return std::make_unique<test::NatsProcess>(IRRADCAST_NATS_CONF);
}

// The file is the test's own: ctest runs tests side by side, and another test writing a wrong
// password to a shared name refused this one's origin.
NatsCredentials user(const std::string& name, const std::string& password) {
  const std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
  const fs::path f = fs::path(::testing::TempDir()) /
                     ("nats_password_" + test + "_" + std::to_string(::getpid()) + "_" + name);
  std::ofstream(f) << password << "\n";
  NatsCredentials c;
  c.user = name;
  c.password_file = f.string();
  return c;
}

// A raw libnats connection as `name` (empty: anonymous); null when refused.
natsConnection* connect_as(const std::string& url, const std::string& name,
                           const std::string& password) {
  natsOptions* o = nullptr;
  natsOptions_Create(&o);
  natsOptions_SetURL(o, url.c_str());
  natsOptions_SetTimeout(o, 2000);
  natsOptions_SetMaxReconnect(o, 0);
  if (!name.empty()) natsOptions_SetUserInfo(o, name.c_str(), password.c_str());
  natsConnection* nc = nullptr;
  const natsStatus s = natsConnection_Connect(&nc, o);
  natsOptions_Destroy(o);
  if (s != NATS_OK) {
    natsConnection_Destroy(nc);
    return nullptr;
  }
  return nc;
}

// A JetStream publish that waits at most 1 s for the stream's acknowledgement.
natsStatus js_publish(jsCtx* js, const std::string& subject, const std::string& bytes) {
  jsPubOptions po;
  jsPubOptions_Init(&po);
  po.MaxWait = 1000;
  jsPubAck* ack = nullptr;
  jsErrCode jerr = static_cast<jsErrCode>(0);
  const natsStatus s = js_Publish(&ack, js, subject.c_str(), bytes.data(),
                                  static_cast<int>(bytes.size()), &po, &jerr);
  jsPubAck_Destroy(ack);
  return s;
}

TEST(NatsSecurity, TheShippedConfigRefusesEachAttackAndEachRoleWorks) {
  IRRADCAST_NEED_NATS();
  auto nats = secured_nats();
  const std::string url = nats->url();
  const NatsSubjects subj = nats_subjects("cornell");

  // Nobody connects without a password, or with a wrong one.
  EXPECT_EQ(connect_as(url, "", ""), nullptr) << "an anonymous connection was accepted";
  EXPECT_EQ(connect_as(url, "gateway", "wrong-password"), nullptr);

  // The roles: an origin and a gateway with their credentials; viewers converge, edits apply.
  test::NatsOriginNode origin(url, 1, kToken, user("origin", kOriginPassword));
  ASSERT_TRUE(origin.settle()) << nats->output();
  test::NatsGatewayNode gw(url, kToken, user("gateway", kGatewayPassword));
  ViewClientOptions vo = test::client_of(*gw.server, "secured-viewer");
  ViewClient viewer(vo);
  viewer.connect();
  EXPECT_TRUE(test::converge(viewer, origin.host.tiles())) << nats->output();

  // A gateway credential cannot listen to the scene's subjects (another gateway's edits).
  natsConnection* spy = connect_as(url, "gateway", kGatewayPassword);
  ASSERT_NE(spy, nullptr);
  natsSubscription* sub = nullptr;
  natsConnection_SubscribeSync(&sub, spy, "irradcast.>");
  natsConnection_Flush(spy);
  EXPECT_EQ(gw.gateway.submit_edit(
                parse_edit_json(R"({"op": "move", "node": "tall_block", "by": [0, 0.01, 0]})")),
            1u);
  EXPECT_TRUE(test::eventually([&] { return origin.host.revision() == 1; }));
  natsMsg* seen = nullptr;
  EXPECT_NE(natsSubscription_NextMsg(&seen, sub, 1500), NATS_OK) << "the spy read a request";
  natsMsg_Destroy(seen);
  natsSubscription_Destroy(sub);

  // It cannot publish a tile (at a version the origin could never overtake), an edit or a state.
  jsCtx* js = nullptr;
  ASSERT_EQ(natsConnection_JetStream(&js, spy, nullptr), NATS_OK);
  wire::NatsTile forged;
  forged.set_origin(1);
  forged.set_index(0);
  forged.set_version(std::uint64_t{1} << 62);
  forged.set_payload("not a tile");
  EXPECT_NE(js_publish(js, subj.tile(0), forged.SerializeAsString()), NATS_OK);
  EXPECT_NE(js_publish(js, subj.edit, "forged edit"), NATS_OK);
  EXPECT_NE(js_publish(js, subj.state, "forged state"), NATS_OK);
  // Nor delete or purge the stream.
  jsErrCode jerr = static_cast<jsErrCode>(0);
  jsOptions quick;
  jsOptions_Init(&quick);
  quick.Wait = 1000;
  EXPECT_NE(js_DeleteStream(js, subj.stream.c_str(), &quick, &jerr), NATS_OK);
  EXPECT_NE(js_PurgeStream(js, subj.stream.c_str(), &quick, &jerr), NATS_OK);
  jsCtx_Destroy(js);
  natsConnection_Destroy(spy);

  // The origin's credential cannot delete the stream either.
  natsConnection* as_origin = connect_as(url, "origin", kOriginPassword);
  ASSERT_NE(as_origin, nullptr);
  ASSERT_EQ(natsConnection_JetStream(&js, as_origin, nullptr), NATS_OK);
  EXPECT_NE(js_DeleteStream(js, subj.stream.c_str(), &quick, &jerr), NATS_OK);
  jsCtx_Destroy(js);
  natsConnection_Destroy(as_origin);

  // The admin reads the stream: it is whole, and its tile 0 is the origin's.
  natsConnection* admin = connect_as(url, "admin", kAdminPassword);
  ASSERT_NE(admin, nullptr);
  ASSERT_EQ(natsConnection_JetStream(&js, admin, nullptr), NATS_OK);
  natsMsg* last = nullptr;
  ASSERT_EQ(js_GetLastMsg(&last, js, subj.stream.c_str(), subj.tile(0).c_str(), nullptr, &jerr),
            NATS_OK);
  wire::NatsTile held;
  ASSERT_TRUE(held.ParseFromArray(natsMsg_GetData(last), natsMsg_GetDataLength(last)));
  EXPECT_LT(held.version(), std::uint64_t{1} << 62);
  natsMsg_Destroy(last);
  jsCtx_Destroy(js);
  natsConnection_Destroy(admin);
  EXPECT_LT(gw.gateway.tiles().version(0), std::uint64_t{1} << 62);
  EXPECT_TRUE(test::converge(viewer, origin.host.tiles()));
  viewer.close();
}

TEST(NatsSecurity, CredentialsAreCheckedAndUserInfoIsNeverLogged) {
  // Combinations that cannot work are errors before anything connects.
  NatsCredentials c;
  c.user = "origin";
  EXPECT_THROW(c.validate(), Error);
  c = user("origin", "x");
  c.creds_file = c.password_file;
  EXPECT_THROW(c.validate(), Error);
  c = {};
  c.tls_cert = "cert.pem";
  EXPECT_THROW(c.validate(), Error);
  c = {};
  c.nkey_file = "/nonexistent/seed";
  EXPECT_THROW(c.validate(), Error);
  EXPECT_TRUE(NatsCredentials{}.tls("tls://127.0.0.1:4222"));
  EXPECT_FALSE(NatsCredentials{}.tls("nats://127.0.0.1:4222"));
  EXPECT_EQ(redact_nats_url("nats://user:secret@host:4222"), "nats://***@host:4222");
  EXPECT_EQ(redact_nats_url("nats://a:b@h1:1,nats://h2:2,tls://c@h3:3"),
            "nats://***@h1:1,nats://h2:2,tls://***@h3:3");
  EXPECT_EQ(redact_nats_url("nats://host:4222"), "nats://host:4222");
  EXPECT_THROW(nkey_public_key("SUAAAA"), Error);
  EXPECT_THROW(nkey_public_key("not base32!"), Error);
}

// A user NKey seed of 32 random bytes, encoded as NATS does (base32 of the seed and user
// prefixes, the bytes and a CRC-16/XMODEM).
std::string random_user_seed() {
  std::vector<std::uint8_t> raw = {(18 << 3) | (160 >> 5), (160 & 31) << 3};
  std::random_device rd;
  for (int i = 0; i < 32; ++i) raw.push_back(static_cast<std::uint8_t>(rd()));
  std::uint16_t crc = 0;
  for (std::uint8_t b : raw) {
    crc = static_cast<std::uint16_t>(crc ^ (b << 8));
    for (int k = 0; k < 8; ++k)
      crc = static_cast<std::uint16_t>((crc & 0x8000) ? (crc << 1) ^ 0x1021 : crc << 1);
  }
  raw.push_back(static_cast<std::uint8_t>(crc & 0xFF));
  raw.push_back(static_cast<std::uint8_t>(crc >> 8));
  const char* alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZ234567";
  std::string out;
  std::uint32_t buffer = 0;
  int bits = 0;
  for (std::uint8_t b : raw) {
    buffer = (buffer << 8) | b;
    bits += 8;
    while (bits >= 5) {
      bits -= 5;
      out += alphabet[(buffer >> bits) & 31];
    }
  }
  if (bits > 0) out += alphabet[(buffer << (5 - bits)) & 31];
  return out;
}

// --nats-nkey: the origin signs NATS's challenge with the seed's key; nats-server knows only the
// public key that nkey_public_key derived, so a wrong derivation would be refused.
TEST(NatsSecurity, AnOriginConnectsWithAnNKeySeed) {
  IRRADCAST_NEED_NATS();
  const std::string seed = random_user_seed();
  ASSERT_EQ(seed.rfind("SU", 0), 0u) << seed;
  const std::string pub = nkey_public_key(seed);
  ASSERT_EQ(pub.rfind("U", 0), 0u) << pub;
  EXPECT_EQ(pub.size(), 56u);
  const fs::path dir = fs::path(::testing::TempDir());
  std::ofstream(dir / "nkey.conf") << "jetstream { store_dir: \"/data\" }\n"
                                   << "authorization { users: [ { nkey: " << pub << " } ] }\n";
  std::ofstream(dir / "origin.nk") << seed << "\n";
  test::NatsProcess nats((dir / "nkey.conf").string());
  EXPECT_EQ(connect_as(nats.url(), "", ""), nullptr);
  NatsCredentials c;
  c.nkey_file = (dir / "origin.nk").string();
  test::NatsOriginNode origin(nats.url(), 1, "", c);
  EXPECT_TRUE(origin.settle()) << nats.output();
  EXPECT_GE(origin.origin.nats_stats().packages_published, 1u);
}

// irradcast-server --nats nats://origin:PASSWORD@...: connects (the URL's user info works) and
// never prints the password.
TEST(NatsSecurity, TheOriginsLogNeverShowsThePasswordOfItsUrl) {
  IRRADCAST_NEED_NATS();
  auto nats = secured_nats();
  const std::string url =
      "nats://origin:" + kOriginPassword + "@127.0.0.1:" + std::to_string(nats->port());
  test::Process server(
      test::command(IRRADCAST_SERVER_EXE,
                    "--scene cornell --bind 127.0.0.1 --port 0 --texels-per-scene 32 "
                    "--max-updates 1 --threads 1 --io-threads 1 --status-every 1 --nats " +
                        url),
      fs::path(::testing::TempDir()) / "nats_redacted.log");
  EXPECT_TRUE(test::eventually(
      [&] { return server.output().find("connected to") != std::string::npos; }, 20s))
      << server.output();
  std::this_thread::sleep_for(1500ms);
  server.signal(SIGINT);
  server.wait_for(10s);
  const std::string log = server.output();
  EXPECT_EQ(log.find(kOriginPassword), std::string::npos) << log;
  EXPECT_NE(log.find("nats://***@127.0.0.1"), std::string::npos) << log;
}

// tls:// to a server without TLS never connects (no silent fall-back to clear text).
TEST(NatsSecurity, TlsIsNeverDowngraded) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess plain;
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  NatsOriginOptions o;
  o.url = "tls://127.0.0.1:" + std::to_string(plain.port());
  try {  // refused at once, or retried in the background without ever connecting
    NatsOrigin origin(host, o);
    std::this_thread::sleep_for(2s);
    EXPECT_FALSE(origin.nats_stats().connected);
    EXPECT_EQ(origin.nats_stats().packages_published, 0u);
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("tls://127.0.0.1"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace irradcast::test_nats_security

namespace irradcast::test_nats_security {
namespace {

// What NATS's permissions cannot stop on an open NATS (or with a stolen credential) is bounded
// by the programs themselves: an origin notices its stream deleted or purged and publishes it
// again; a gateway refuses a tile version the origin cannot have made; an origin holds the
// cameras of at most max_gateways gateways.
TEST(NatsHardening, AnOriginRepublishesADeletedOrPurgedStream) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 1);
  ASSERT_TRUE(origin.settle());
  const NatsSubjects subj = nats_subjects("cornell");
  natsConnection* nc = nullptr;
  ASSERT_EQ(natsConnection_ConnectTo(&nc, nats.url().c_str()), NATS_OK);
  jsCtx* js = nullptr;
  ASSERT_EQ(natsConnection_JetStream(&js, nc, nullptr), NATS_OK);
  jsErrCode jerr = static_cast<jsErrCode>(0);
  for (const bool purge : {false, true}) {
    const std::uint64_t losses = origin.origin.nats_stats().stream_losses;
    ASSERT_EQ(purge ? js_PurgeStream(js, subj.stream.c_str(), nullptr, &jerr)
                    : js_DeleteStream(js, subj.stream.c_str(), nullptr, &jerr),
              NATS_OK);
    EXPECT_TRUE(test::eventually([&] {
      return origin.origin.nats_stats().stream_losses > losses &&
             origin.origin.flush(std::chrono::milliseconds(500));
    })) << (purge ? "purge" : "delete");
    // A gateway that starts now gets the whole scene from the stream.
    test::NatsGatewayNode late(nats.url());
    ViewClient v(test::client_of(*late.server, "late"));
    v.connect();
    EXPECT_TRUE(test::converge(v, origin.host.tiles())) << (purge ? "purge" : "delete");
    v.close();
  }
  jsCtx_Destroy(js);
  natsConnection_Destroy(nc);
}

TEST(NatsHardening, AGatewayRefusesATileVersionTheOriginCannotHaveMade) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  test::NatsOriginNode origin(nats.url(), 2);
  ASSERT_TRUE(origin.settle());
  test::NatsGatewayNode gw(nats.url());
  ASSERT_TRUE(test::eventually([&] { return gw.gateway.stats().updates >= 2; }));
  const std::uint64_t bad = gw.gateway.nats_stats().bad_messages;
  natsConnection* nc = nullptr;
  ASSERT_EQ(natsConnection_ConnectTo(&nc, nats.url().c_str()), NATS_OK);
  jsCtx* js = nullptr;
  ASSERT_EQ(natsConnection_JetStream(&js, nc, nullptr), NATS_OK);
  const TileStore::Snapshot real = origin.host.tiles().snapshot(0, wire::TILE_RGB9E5_ZSTD);
  ASSERT_GT(real.version, 0u);
  wire::NatsTile forged;
  forged.set_origin(1);
  forged.set_index(0);
  forged.set_version(std::uint64_t{1} << 62);
  forged.set_time_us(real.time_us);
  forged.set_payload(*real.payload);  // a valid tile, at a version no origin reaches
  EXPECT_EQ(js_publish(js, nats_subjects("cornell").tile(0), forged.SerializeAsString()), NATS_OK);
  EXPECT_TRUE(test::eventually([&] { return gw.gateway.nats_stats().bad_messages > bad; }));
  EXPECT_EQ(gw.gateway.tiles().version(0), real.version);
  jsCtx_Destroy(js);
  natsConnection_Destroy(nc);
}

TEST(NatsHardening, AnOriginHoldsTheCamerasOfAtMostMaxGatewaysGateways) {
  IRRADCAST_NEED_NATS();
  test::NatsProcess nats;
  EngineHost host(make_cornell_box(), "cornell", test::quick_host(1));
  NatsOriginOptions o;
  o.url = nats.url();
  o.max_gateways = 2;
  NatsOrigin origin(host, o);
  ASSERT_TRUE(test::eventually([&] { return origin.nats_stats().connected; }));
  natsConnection* nc = nullptr;
  ASSERT_EQ(natsConnection_ConnectTo(&nc, nats.url().c_str()), NATS_OK);
  // The origin's answer to a camera request from `gateway` (nullopt: none yet).
  auto ask = [&](std::uint64_t gateway) -> std::optional<wire::NatsReply> {
    wire::NatsCameras m;
    m.set_gateway(gateway);
    wire::CameraUpdate* c = m.add_cameras();
    c->mutable_eye()->set_z(3.0f);
    c->mutable_forward()->set_z(-1.0f);
    c->mutable_up()->set_y(1.0f);
    c->set_yfov(0.8f);
    const std::string bytes = m.SerializeAsString();
    natsMsg* reply = nullptr;
    if (natsConnection_Request(&reply, nc, nats_subjects("cornell").cameras.c_str(), bytes.data(),
                               static_cast<int>(bytes.size()), 2000) != NATS_OK)
      return std::nullopt;
    wire::NatsReply r;
    r.ParseFromArray(natsMsg_GetData(reply), natsMsg_GetDataLength(reply));
    natsMsg_Destroy(reply);
    return r;
  };
  // Until the origin's subscription is in place, requests find no responder.
  std::optional<wire::NatsReply> first;
  ASSERT_TRUE(test::eventually([&] { return (first = ask(11)).has_value(); }));
  EXPECT_EQ(first->code(), wire::ERROR_UNSPECIFIED);
  EXPECT_EQ(ask(12).value_or(wire::NatsReply{}).code(), wire::ERROR_UNSPECIFIED);
  const wire::NatsReply third = ask(13).value_or(wire::NatsReply{});
  EXPECT_EQ(third.code(), wire::REFUSED);
  EXPECT_NE(third.error().find("2 gateways already"), std::string::npos) << third.error();
  EXPECT_EQ(ask(11).value_or(wire::NatsReply{}).code(), wire::ERROR_UNSPECIFIED);  // held: goes on
  EXPECT_EQ(origin.nats_stats().gateways_refused, 1u);
  natsConnection_Destroy(nc);
}

}  // namespace
}  // namespace irradcast::test_nats_security
