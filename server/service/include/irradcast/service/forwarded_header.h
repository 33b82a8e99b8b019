// The header a trusted reverse proxy writes its clients' addresses in (ServerOptions,
// --forwarded-header; docs/OPERATIONS.md "Behind a proxy").
#pragma once

namespace irradcast {

enum class ForwardedHeader { XForwardedFor, Forwarded };

}  // namespace irradcast
