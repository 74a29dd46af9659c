#pragma once
/// The real libc functions behind an interposition library's wrappers (libwheelhil_ucan.so,
/// libwheelhil_vtime.so): `REAL_FN(poll, int, (pollfd*, nfds_t, int))` declares real_poll(),
/// the next `poll` after the calling library in the dynamic linker's search order (dlsym
/// RTLD_NEXT), resolved on first use and cached. REAL_FN_V picks a symbol version (symbols with
/// an old and a current version, where dlsym may give the old). Include inside an anonymous
/// namespace of the library's one translation unit. Thread-safe (a race resolves twice).

#include <dlfcn.h>

namespace wheelhil::bus::interpose {

template <typename F>
F Resolve(F& slot, const char* name, const char* version = nullptr) {
  F f = __atomic_load_n(&slot, __ATOMIC_ACQUIRE);
  if (f == nullptr) {
    void* p = version != nullptr ? dlvsym(RTLD_NEXT, name, version) : nullptr;
    if (p == nullptr) p = dlsym(RTLD_NEXT, name);
    f = reinterpret_cast<F>(p);
    __atomic_store_n(&slot, f, __ATOMIC_RELEASE);
  }
  return f;
}

}  // namespace wheelhil::bus::interpose

#define REAL_FN(name, ret, params)                                    \
  using name##_fn = ret(*) params;                                    \
  name##_fn g_real_##name = nullptr;                                  \
  inline name##_fn real_##name() {                                    \
    return ::wheelhil::bus::interpose::Resolve(g_real_##name, #name); \
  }

#define REAL_FN_V(name, ret, params, version)                                  \
  using name##_fn = ret(*) params;                                             \
  name##_fn g_real_##name = nullptr;                                           \
  inline name##_fn real_##name() {                                             \
    return ::wheelhil::bus::interpose::Resolve(g_real_##name, #name, version); \
  }
