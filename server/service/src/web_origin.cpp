#include "irradcast/service/web_origin.h"

#include <cctype>
#include <cstring>
#include <utility>

#include "irradcast/common/error.h"

namespace irradcast {

namespace {
std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}
// "https://Example.com:443/" -> "https://example.com" (scheme, host and a non-default port).
std::string normal_origin(std::string origin) {
  origin = lower(std::move(origin));
  while (!origin.empty() && origin.back() == '/') origin.pop_back();
  for (const auto& [scheme, port] :
       {std::pair<const char*, const char*>{"http://", ":80"}, {"https://", ":443"}})
    if (origin.rfind(scheme, 0) == 0 && origin.size() > std::strlen(port) &&
        origin.compare(origin.size() - std::strlen(port), std::string::npos, port) == 0)
      origin.resize(origin.size() - std::strlen(port));
  return origin;
}
}  // namespace

void check_origin(const std::string& origin) {
  if (origin == "null") return;
  const std::string o = lower(origin);
  const std::size_t at = o.find("://");
  const std::string scheme = at == std::string::npos ? "" : o.substr(0, at);
  const std::string authority = at == std::string::npos ? "" : o.substr(at + 3);
  const bool ok = (scheme == "http" || scheme == "https") && !authority.empty() &&
                  authority.find_first_of("/?#@ ") == std::string::npos;
  if (!ok)
    throw Error("--allowed-origin '" + origin +
                "' is not an origin (scheme://host[:port], http or https, or null)");
}

bool origin_allowed(const std::string& origin, const std::string& host,
                    const std::vector<std::string>& allowed) {
  const std::string o = normal_origin(origin);
  for (const std::string& a : allowed)
    if (normal_origin(a) == o) return true;
  if (o == "null" || host.empty()) return false;
  for (const char* scheme : {"http://", "https://"})
    if (o == normal_origin(scheme + host)) return true;
  return false;
}

}  // namespace irradcast
