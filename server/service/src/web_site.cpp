// The viewer page's files over HTTP: only the names of the embedded table, GET and HEAD only.
#include "web_site.h"

#include <string_view>

#include "irradcast/web/assets.h"

namespace irradcast {

const char* const kWebContentSecurityPolicy =
    "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data: blob:; connect-src 'self'; worker-src 'self' blob:; "
    "object-src 'none'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

namespace {

// Headers on every reply: no sniffing, no framing, no referrer, no caching without asking (the
// embedded files change with the server binary and carry no version in their names).
wire::HttpReply reply(int status, std::string content_type, std::string body) {
  wire::HttpReply r;
  r.status = status;
  r.headers = {{"Content-Type", std::move(content_type)},
               {"Cache-Control", "no-cache"},
               {"X-Content-Type-Options", "nosniff"},
               {"X-Frame-Options", "DENY"},
               {"Referrer-Policy", "no-referrer"},
               {"Cross-Origin-Opener-Policy", "same-origin"},
               {"Content-Security-Policy", kWebContentSecurityPolicy}};
  r.body = std::move(body);
  return r;
}

wire::HttpReply text(int status, const std::string& message) {
  return reply(status, "text/plain; charset=utf-8", message + "\n");
}

}  // namespace

wire::HttpReply serve_web(const std::string& method, const std::string& target) {
  if (method != "GET" && method != "HEAD") {
    wire::HttpReply r = text(405, "method not allowed: the viewer's files take GET and HEAD");
    r.headers.emplace_back("Allow", "GET, HEAD");
    return r;
  }
  // The path: the target up to its query; only an origin-form target ("/...") names a file.
  const std::string_view path = std::string_view(target).substr(0, target.find_first_of("?#"));
  const web::Asset* asset = path.empty() || path[0] != '/' ? nullptr : web::find_asset(path);
  if (!asset) return text(404, "not found");
  wire::HttpReply r = reply(200, std::string(asset->content_type),
                            method == "HEAD" ? std::string() : std::string(asset->body));
  return r;
}

}  // namespace irradcast
