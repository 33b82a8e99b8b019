// Which web pages may open the web port's WebSocket (docs/OPERATIONS.md "The web port"): a page
// in a visitor's browser that belongs to another site must not download an intranet server's
// scene through that visitor. Browsers send the page's origin in the upgrade's Origin header.
#pragma once

#include <string>
#include <vector>

namespace irradcast {

// Whether a WebSocket upgrade from a page of `origin` (its Origin header) may open on a server
// reached as `host` (the Host header): the page's own origin (scheme://host[:port], the same
// authority as Host, default ports ignored), or one listed in `allowed` (--allowed-origin,
// compared exactly, case-insensitive, a trailing / ignored). "null" (sandboxed pages, files) only
// when listed.
bool origin_allowed(const std::string& origin, const std::string& host,
                    const std::vector<std::string>& allowed);
// Throws irradcast::Error unless `origin` is scheme://host[:port] with scheme http or https (an
// --allowed-origin value), or "null".
void check_origin(const std::string& origin);

}  // namespace irradcast
