// A SessionProtocol driven without sockets, as a client would: frames fed in, and the frames it
// writes now read back (the unit tests of poses and presence).
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "irradcast/wire/frame.h"
#include "session_protocol.h"

namespace irradcast::test {

// Feeds one frame and handles what it decodes to.
inline void feed(SessionProtocol& s, const wire::Envelope& e) {
  const std::string bytes = wire::encode_frame(e);
  s.receive(bytes.data(), bytes.size());
  wire::Envelope env;
  while (s.next_frame(env)) s.handle(env);
}

// A new session of `context` (the `n`-th, from 10.0.0.1) that has said Hello, and with
// `subscribe` subscribed to every tile (`presence`: shown to the others).
inline std::unique_ptr<SessionProtocol> joined(SessionContext& context, std::size_t n,
                                               bool subscribe, bool presence = false) {
  auto s = std::make_unique<SessionProtocol>(context, n, "10.0.0.1", "10.0.0.1:5000");
  wire::Envelope h;
  h.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
  feed(*s, h);
  if (subscribe) {
    wire::Envelope sub;
    sub.mutable_subscribe()->set_all(true);
    if (presence) sub.mutable_subscribe()->set_presence(true);
    feed(*s, sub);
  }
  return s;
}

// The frames the session writes now, in order, until it has none; those `keep` refuses are
// left out.
template <class Keep>
std::vector<wire::Envelope> frames_written(SessionProtocol& s, Keep keep) {
  std::vector<wire::Envelope> out;
  for (;;) {
    const SessionWrite w = s.next_write(std::chrono::steady_clock::now());
    if (!w.frame) return out;
    wire::FrameDecoder d;
    d.feed(w.frame->data(), w.frame->size());
    wire::Envelope e;
    EXPECT_EQ(d.next(e), wire::DecodeStatus::Frame);
    if (keep(e)) out.push_back(e);
  }
}

}  // namespace irradcast::test
