#pragma once
/// A function the other of the two preloaded libraries (libwheelhil_ucan.so, libwheelhil_vtime.so)
/// exports, looked up once in the whole process (dlsym RTLD_DEFAULT) and nullptr when that
/// library is not loaded. Declare one per function at namespace scope: the constructor is
/// constexpr, so it needs no initialisation at start-up. Not installed.

#include <dlfcn.h>

#include <atomic>

namespace wheelhil::bus::internal {

template <typename Fn>
class PeerSymbol {
 public:
  explicit constexpr PeerSymbol(const char* name) : name_(name) {}
  Fn get() {
    if (!looked_.load(std::memory_order_acquire)) {
      fn_.store(reinterpret_cast<Fn>(dlsym(RTLD_DEFAULT, name_)));
      looked_.store(true, std::memory_order_release);
    }
    return fn_.load(std::memory_order_relaxed);
  }

 private:
  const char* name_;
  std::atomic<Fn> fn_{nullptr};
  std::atomic<bool> looked_{false};
};

}  // namespace wheelhil::bus::internal
