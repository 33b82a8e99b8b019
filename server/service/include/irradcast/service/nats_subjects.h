// The NATS subjects and the JetStream stream of one scene (docs/DISTRIBUTION.md): what an origin
// (irradcast-server --nats) publishes and answers, and what a gateway (irradcast-gateway)
// consumes and asks. The scene id becomes one subject token: characters other than letters,
// digits, '-' and '_' become '_', and a changed id gets 8 hex digits of its hash appended, so
// that "rooms:2" and "rooms_2" stay apart.
#pragma once

#include <cstdint>
#include <string>

namespace irradcast {

struct NatsSubjects {
  std::string token;   // the scene id as a subject token
  std::string stream;  // IRRADCAST_<token>: the scene's stream, one message per subject
  // In the stream (irradcast.<token>.s.*, the latest message of each subject kept):
  std::string filter;          // irradcast.<token>.s.> : all of them
  std::string state;           // irradcast.<token>.s.state : NatsSceneState
  std::string package_prefix;  // irradcast.<token>.s.package. + chunk index: NatsPackageChunk
  std::string tile_prefix;     // irradcast.<token>.s.tile. + tile index: NatsTile
  std::string edit;            // irradcast.<token>.s.edit : NatsEdit (the last applied edit)
  std::string stats;           // irradcast.<token>.s.stats : wire::Stats (the engine's part)
  std::string volume;          // irradcast.<token>.s.volume : NatsVolume (after its chunks)
  std::string volume_prefix;   // irradcast.<token>.s.volchunk. + index: NatsVolumeChunk
  std::string poses;           // irradcast.<token>.s.poses : NatsPoses
  std::string presence;        // irradcast.<token>.s.presence : NatsPresence
  // Requests to the origin (core NATS request/reply, not stored):
  std::string cameras;  // irradcast.<token>.req.cameras : NatsCameras -> NatsReply
  std::string submit;   // irradcast.<token>.req.edit : SceneEdit with the token -> NatsReply

  std::string package_chunk(std::uint32_t i) const { return package_prefix + std::to_string(i); }
  std::string tile(std::uint32_t i) const { return tile_prefix + std::to_string(i); }
  std::string volume_chunk(std::uint32_t i) const { return volume_prefix + std::to_string(i); }
};

NatsSubjects nats_subjects(const std::string& scene_id);

}  // namespace irradcast
