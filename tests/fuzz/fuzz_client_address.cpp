// libFuzzer target for what a proxy (or a peer pretending to be one) says about its clients
// (server/service/src/client_address.h): arbitrary bytes as a PROXY protocol v2 header fed in
// arbitrary pieces, and as X-Forwarded-For and Forwarded header values.
// Properties checked beyond "no crash, no leak, no UB":
//  - the reader keeps every byte: the header's bytes plus rest() are exactly what was fed, and a
//    connection without a header gets back all of it;
//  - it never asks for more than kMaxHeaderBytes before deciding;
//  - a client named by a header is never a trusted address.
// Run: deploy/fuzz.sh (or build-fuzz/tests/fuzz/fuzz_client_address -max_total_time=30).
#include <fuzzer/FuzzedDataProvider.h>

#include <cstdint>
#include <cstdlib>
#include <string>

#include "client_address.h"

using namespace irradcast;

namespace {

void check(bool ok) {
  if (!ok) std::abort();
}

const TrustedProxies& trusted() {
  static const TrustedProxies t({"10.0.0.0/8", "127.0.0.1", "fd00::/8"});
  return t;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  FuzzedDataProvider in(data, size);
  const bool with_signature = in.ConsumeBool();
  std::string fed = with_signature ? std::string("\r\n\r\n\0\r\nQUIT\n", 12) : std::string();
  ProxyHeaderReader r;
  ProxyHeaderReader::State state = r.feed(fed.data(), fed.size());
  while (state == ProxyHeaderReader::State::More && in.remaining_bytes() > 0) {
    const std::string piece = in.ConsumeRandomLengthString(64);
    fed += piece;
    state = r.feed(piece.data(), piece.size());
  }
  check(fed.size() <= ProxyHeaderReader::kMaxHeaderBytes + 64 ||
        state != ProxyHeaderReader::State::More);
  if (state == ProxyHeaderReader::State::None) check(r.take_rest() == fed);
  if (state == ProxyHeaderReader::State::Done) {
    const std::string rest = r.take_rest();
    const std::size_t header =
        16 + ((std::size_t(std::uint8_t(fed[14])) << 8) | std::uint8_t(fed[15]));
    check(header + rest.size() == fed.size() && fed.compare(header, rest.size(), rest) == 0);
  }
  if (state == ProxyHeaderReader::State::Bad) check(!r.error().empty());

  const std::string header = in.ConsumeBytesAsString(in.remaining_bytes());
  for (const ForwardedHeader which : {ForwardedHeader::XForwardedFor, ForwardedHeader::Forwarded}) {
    const ForwardedClient client = forwarded_client(header, which, trusted());
    if (client.kind == ForwardedClient::Kind::Client) check(!trusted().contains(client.address));
  }
  parse_forwarded_address(header);
  return 0;
}
