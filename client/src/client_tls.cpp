#include "irradcast/client/client_tls.h"

namespace irradcast {

std::shared_ptr<asio::ssl::context> make_tls_context(const ClientTls& tls) {
  if (!tls.enabled) {
    return nullptr;
  }
  return wire::make_client_tls(tls.ca_file);
}

}  // namespace irradcast
