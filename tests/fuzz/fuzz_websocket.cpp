// libFuzzer target for the web port's HTTP and WebSocket layer (wire/websocket.h, websocketpp):
// arbitrary bytes, after a valid upgrade request or on their own, fed in arbitrary pieces.
// Properties checked beyond "no crash, no leak, no UB":
//  - no message above the cap reaches the handler;
//  - once the connection has ended, more bytes change nothing (no handler runs, no output);
//  - the HTTP handler only sees requests while no WebSocket is open.
// Run: deploy/fuzz.sh (or build-fuzz/tests/fuzz/fuzz_websocket -max_total_time=30).
#include <fuzzer/FuzzedDataProvider.h>

#include <cstdint>
#include <cstdlib>
#include <string>

#include "irradcast/wire/websocket.h"

using namespace irradcast::wire;

namespace {

void check(bool ok) {
  if (!ok) std::abort();
}

const char kUpgrade[] =
    "GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n";

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  FuzzedDataProvider in(data, size);
  const std::size_t cap = in.ConsumeIntegralInRange<std::size_t>(0, 4096);
  const bool upgrade = in.ConsumeBool();
  bool handler_ran = false;
  WsServerConnection* self = nullptr;
  WsServerConnection::Handlers h;
  h.http = [&](const std::string&, const std::string&) {
    check(self && !self->is_open());
    handler_ran = true;
    HttpReply r;
    r.status = 200;
    r.body = "page";
    return r;
  };
  h.binary = [&](std::string payload) {
    check(payload.size() <= cap);
    handler_ran = true;
  };
  WsServerConnection c(h, cap);
  self = &c;
  if (upgrade) c.receive(kUpgrade, sizeof kUpgrade - 1);
  while (in.remaining_bytes() > 0) {
    const std::string piece = in.ConsumeRandomLengthString(256);
    const bool ended = c.end() != WsServerConnection::End::None;
    handler_ran = false;
    c.take_output();
    c.receive(piece.data(), piece.size());
    if (ended) check(!handler_ran && !c.has_output());
  }
  return 0;
}
