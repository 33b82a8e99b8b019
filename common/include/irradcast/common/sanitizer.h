// IRRADCAST_ASAN: 1 in a build with AddressSanitizer, from GCC (__SANITIZE_ADDRESS__) or clang
// (__has_feature; clang 14 does not define GCC's macro), else 0.
#pragma once

#if defined(__SANITIZE_ADDRESS__)
#define IRRADCAST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define IRRADCAST_ASAN 1
#endif
#endif
#ifndef IRRADCAST_ASAN
#define IRRADCAST_ASAN 0
#endif
