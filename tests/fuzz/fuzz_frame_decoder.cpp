// libFuzzer target for the frame decoder: arbitrary bytes, fed in arbitrary pieces, with a small
// or the default frame cap. Properties checked beyond "no crash, no leak, no UB":
//  - every decoded Envelope re-encodes to a frame that decodes to the same bytes again;
//  - TooLarge / Malformed are sticky and come with an error() message;
//  - the decoder never holds more than what was fed and not yet consumed.
// Run: deploy/fuzz.sh (or build-fuzz/tests/fuzz/fuzz_frame_decoder -max_total_time=30).
#include <fuzzer/FuzzedDataProvider.h>

#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include <google/protobuf/stubs/logging.h>

#include "irradcast/wire/frame.h"

using namespace irradcast::wire;

namespace {

void check(bool ok) {
  if (!ok) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // Invalid UTF-8 in string fields is a parse failure; protobuf also logs it. Keep the output
  // readable.
  google::protobuf::SetLogHandler(nullptr);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  FuzzedDataProvider in(data, size);
  const bool small_cap = in.ConsumeBool();
  const std::size_t max_frame =
      small_cap ? in.ConsumeIntegralInRange<std::size_t>(0, 4096) : kDefaultMaxFrame;
  FrameDecoder decoder(max_frame);
  std::size_t fed = 0, consumed = 0;
  Envelope out;
  bool broken = false;
  DecodeStatus broken_status = DecodeStatus::NeedMore;
  while (in.remaining_bytes() > 0) {
    const std::size_t piece = in.ConsumeIntegralInRange<std::size_t>(1, 64);
    const std::vector<std::uint8_t> bytes = in.ConsumeBytes<std::uint8_t>(piece);
    decoder.feed(bytes.data(), bytes.size());
    fed += bytes.size();
    for (;;) {
      const std::size_t before = decoder.buffered();
      const DecodeStatus st = decoder.next(out);
      if (broken) {
        check(st == broken_status);
        break;
      }
      if (st == DecodeStatus::NeedMore) {
        check(decoder.buffered() == before);
        break;
      }
      if (st == DecodeStatus::TooLarge || st == DecodeStatus::Malformed) {
        check(!decoder.error().empty());
        broken = true;
        broken_status = st;
        break;
      }
      // A frame: consumed header + payload; it survives a re-encode exactly.
      consumed += before - decoder.buffered();
      check(before - decoder.buffered() >= kFrameHeaderBytes);
      check(message_name(out) != nullptr);
      const std::string again = encode_frame(out, SIZE_MAX);
      FrameDecoder second(SIZE_MAX);
      second.feed(again.data(), again.size());
      Envelope copy;
      check(second.next(copy) == DecodeStatus::Frame);
      check(copy.SerializeAsString() == out.SerializeAsString());
      check(copy.msg_case() == out.msg_case());
    }
    if (!broken) check(decoder.buffered() == fed - consumed);
  }
  return 0;
}
