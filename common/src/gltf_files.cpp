// glTF import: external files. Every buffer and image URI must name a regular file inside the
// scene file's folder (or the root the caller gives), after following symlinks: a scene must not
// make the server read (and send to every client) a file elsewhere, nor block on a FIFO or a
// device. check_uris() refuses such a URI by name before tinygltf runs; tinygltf then reads files
// only through the callbacks below, which apply the same rule (and never look in the working
// directory, which tinygltf tries after the base folder).
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "gltf_import.h"

namespace irradcast::gltf_import {
namespace {

namespace fs = std::filesystem;

// What tinygltf (dlib::urldecode) makes of a URI before it joins it to the folder: %XX decoded,
// '+' read as a space.
std::string decode_uri(const std::string& uri) {
  auto hex = [](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return 0;  // as tinygltf does
  };
  std::string out;
  for (std::size_t i = 0; i < uri.size(); ++i) {
    if (uri[i] == '+') {
      out += ' ';
    } else if (uri[i] == '%' && uri.size() > i + 2) {
      out += static_cast<char>((hex(uri[i + 1]) << 4) | hex(uri[i + 2]));
      i += 2;
    } else {
      out += uri[i];
    }
  }
  return out;
}

}  // namespace

// Why `file` may not be read ("" if it may): it must resolve, symlinks followed, to a path under
// `root` that is a regular file. A file that does not exist is left to tinygltf ("not found").
std::string refusal(const fs::path& file, const fs::path& root) {
  std::error_code ec;
  const fs::path resolved = fs::weakly_canonical(file, ec);
  if (ec) return "it cannot be resolved (" + ec.message() + ")";
  const fs::path rel = resolved.lexically_relative(root);
  if (rel.empty() || *rel.begin() == "..")
    return "it resolves to " + clean(resolved.string()) + ", outside " + clean(root.string());
  const fs::file_status st = fs::status(resolved, ec);
  if (!fs::exists(st)) return "";
  if (!fs::is_regular_file(st)) return "it is not a regular file";
  return "";
}

namespace {

bool guarded_file_exists(const std::string& file, void* user) {
  auto* g = static_cast<FileGuard*>(user);
  const std::string prefix = g->base.back() == '/' ? g->base : g->base + "/";
  if (file.compare(0, prefix.size(), prefix) != 0) return false;  // e.g. "./uri": never the cwd
  const std::string why = refusal(file, g->root);
  if (!why.empty()) {
    if (g->refused.empty()) g->refused = "'" + clean(file.substr(prefix.size())) + "': " + why;
    return false;
  }
  std::error_code ec;
  return fs::is_regular_file(file, ec);
}

std::string no_expansion(const std::string& file, void*) {
  return file;
}

bool guarded_read(std::vector<unsigned char>* out, std::string* err, const std::string& file,
                  void* user) {
  auto fail = [&](const std::string& why) {
    if (err) *err = why;
    return false;
  };
  if (!guarded_file_exists(file, user)) return fail("refused or not found");
  std::error_code ec;
  const fs::path resolved = fs::canonical(file, ec);
  if (ec) return fail(ec.message());
  // O_NONBLOCK: should the file have become a FIFO since the check, opening it does not block.
  const int fd =
      ::open(resolved.c_str(), O_RDONLY | O_NONBLOCK | O_NOFOLLOW | O_NOCTTY | O_CLOEXEC);
  if (fd < 0) return fail(std::strerror(errno));
  struct stat st {};
  std::string why;
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode))
    why = "not a regular file";
  else if (st.st_size > 0x7fffffff)
    why = "file too large";
  if (why.empty()) {
    out->resize(static_cast<std::size_t>(st.st_size));
    std::size_t got = 0;
    while (got < out->size()) {
      const ssize_t n = ::read(fd, out->data() + got, out->size() - got);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      got += static_cast<std::size_t>(n);
    }
    if (got != out->size()) why = "read error";
  }
  ::close(fd);
  if (!why.empty()) {
    auto* g = static_cast<FileGuard*>(user);
    if (g->refused.empty()) g->refused = "'" + clean(file) + "': " + why;
    return fail(why);
  }
  return true;
}

bool no_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err = "writing files is disabled";
  return false;
}

}  // namespace

FileGuard make_file_guard(const std::string& path, const std::string& root) {
  std::error_code ec;
  FileGuard guard;
  guard.base = fs::absolute(path, ec).parent_path().string();
  if (ec || guard.base.empty()) throw Error(path + ": cannot resolve the file's folder");
  if (root.empty()) {
    guard.root = fs::canonical(guard.base, ec);
    if (ec) throw Error(path + ": cannot resolve the file's folder: " + ec.message());
  } else {
    guard.root = fs::canonical(root, ec);
    if (ec || !fs::is_directory(guard.root, ec))
      throw Error("scene root '" + clean(root) + "': not a directory");
  }
  return guard;
}

tinygltf::FsCallbacks guarded_callbacks(FileGuard* guard) {
  return tinygltf::FsCallbacks{&guarded_file_exists, &no_expansion, &guarded_read, &no_write,
                               guard};
}

void check_uris(const std::string& path, const nlohmann::json& j, const FileGuard& g) {
  for (const char* kind : {"buffers", "images"}) {
    if (!j.contains(kind) || !j[kind].is_array()) continue;
    const nlohmann::json& items = j[kind];
    for (std::size_t i = 0; i < items.size(); ++i) {
      if (!items[i].is_object() || !items[i].contains("uri") || !items[i]["uri"].is_string())
        continue;
      const std::string uri = items[i]["uri"].get<std::string>();
      if (tinygltf::IsDataURI(uri)) continue;
      const std::string file = decode_uri(uri);
      if (file.empty()) continue;
      const std::string why = fs::path(file).is_absolute()
                                  ? "it is an absolute path"
                                  : refusal(fs::path(g.base) / file, g.root);
      if (!why.empty())
        throw Error(path + ": " + (kind[0] == 'b' ? "buffer " : "image ") + std::to_string(i) +
                    " URI '" + clean(uri) + "' is refused: " + why +
                    " (a scene may only read regular files under its folder)");
    }
  }
}

}  // namespace irradcast::gltf_import

namespace irradcast {

std::string confined_file(const std::string& root, const std::string& name,
                          const std::string& what) {
  namespace fs = std::filesystem;
  using gltf_import::clean;
  std::error_code ec;
  const fs::path dir = fs::canonical(root, ec);
  if (ec || !fs::is_directory(dir, ec))
    throw Error(what + ": the folder '" + clean(root) + "' is not a directory");
  std::string why = name.empty()                   ? "no name given"
                    : fs::path(name).is_absolute() ? "it is an absolute path"
                                                   : gltf_import::refusal(dir / name, dir);
  if (why.empty() && !fs::is_regular_file(dir / name, ec)) why = "there is no such file";
  if (!why.empty()) throw Error(what + " '" + clean(name) + "' is refused: " + why);
  return fs::canonical(dir / name).string();
}

}  // namespace irradcast
