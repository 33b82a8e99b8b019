// A client's queue of tiles to send. It holds tile indices, not payloads, and each tile at most
// once: when a tile changes again before it was sent, the entry stays where it is and the client
// gets the newest version when its turn comes (the older one is "coalesced"). A slow client
// therefore costs at most one entry per tile, never a backlog.
#pragma once

#include <cstdint>
#include <deque>
#include <vector>

namespace irradcast {

class SendQueue {
 public:
  explicit SendQueue(std::size_t tiles = 0) : pending_(tiles, 0) {}

  void resize(std::size_t tiles) { pending_.assign(tiles, 0), order_.clear(); }
  // Returns false (and counts a coalesced version) when the tile was already waiting.
  bool push(std::uint32_t tile) {
    if (tile >= pending_.size()) return false;
    if (pending_[tile]) {
      ++coalesced_;
      return false;
    }
    pending_[tile] = 1;
    order_.push_back(tile);
    return true;
  }
  bool pop(std::uint32_t& tile) {
    if (order_.empty()) return false;
    tile = order_.front();
    order_.pop_front();
    pending_[tile] = 0;
    return true;
  }
  std::size_t size() const { return order_.size(); }
  bool empty() const { return order_.empty(); }
  std::uint64_t coalesced() const { return coalesced_; }

 private:
  std::vector<std::uint8_t> pending_;
  std::deque<std::uint32_t> order_;
  std::uint64_t coalesced_ = 0;
};

}  // namespace irradcast
