// The plain HTTP side of the server's web port: the viewer page's embedded files
// (irradcast/web/assets.h) with their content type, caching and security headers; every other
// request gets a short error reply. No request ever reaches the file system.
#pragma once

#include <string>

#include "irradcast/wire/websocket.h"

namespace irradcast {

// The reply to `method` `target` (the request line's target, query included).
wire::HttpReply serve_web(const std::string& method, const std::string& target);

// The Content-Security-Policy the page is served with: its own scripts, styles (inline too),
// images (data: and blob: too) and its own host's WebSocket; no frames, no plugins.
extern const char* const kWebContentSecurityPolicy;

}  // namespace irradcast
