// Fibers on glibc's ucontext (see fiber.hpp).
#include "util/fiber.hpp"

#include "util/error.hpp"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <exception>

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define COROFEM_ASAN 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__)
#define COROFEM_ASAN 1
#endif

#if defined(__GLIBC__)  // makecontext and swapcontext (musl and bionic have neither)
#include <cxxabi.h>
#include <sys/mman.h>
#include <ucontext.h>
#include <unistd.h>
#define COROFEM_UCONTEXT 1
#endif

namespace corofem::detail {

#if defined(COROFEM_UCONTEXT) && !defined(COROFEM_ASAN)

namespace {

/// The Itanium C++ ABI's per-thread exception globals (libstdc++ and libc++abi alike): the
/// exceptions being caught, innermost first, and the count of thrown, not yet caught ones.
struct EhGlobals {
  void* caughtExceptions = nullptr;
  unsigned int uncaughtExceptions = 0;
};

EhGlobals& ehGlobals() { return *reinterpret_cast<EhGlobals*>(abi::__cxa_get_globals()); }

thread_local Fiber* tRunning = nullptr;  ///< the fiber the thread runs now
thread_local Fiber* tEntering = nullptr;  ///< the fiber whose entry() is about to run

}  // namespace

struct Fiber::Context {
  ucontext_t uc;
  EhGlobals eh;
};

namespace {

/// Leaves `from` for `to` on this thread, each with its own exception globals.
void switchContext(Fiber::Context& from, Fiber::Context& to) {
  EhGlobals& g = ehGlobals();
  from.eh = g;
  g = to.eh;
  if (swapcontext(&from.uc, &to.uc) != 0) std::abort();  // only fails for a bad context: a bug here
}

}  // namespace

bool fibersAvailable() { return true; }

Fiber::Fiber(std::size_t stackBytes) : self_(new Context()), host_(new Context()) {
  const std::size_t page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  stackBytes_ = (stackBytes + page - 1) / page * page;
  mapped_ = stackBytes_ + page;
  void* p = mmap(nullptr, mapped_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE | MAP_STACK, -1, 0);
  if (p == MAP_FAILED) {
    delete self_;
    delete host_;
    fail(ErrorCode::Internal, "could not map a fiber stack of ", mapped_, " bytes: ", std::strerror(errno),
         " (set COROFEM_BATCH_FIBERS=0 for a thread per body)");
  }
  // The lowest page traps an overflow (stacks grow down) instead of writing past the stack.
  if (mprotect(p, page, PROT_NONE) != 0) {
    const int err = errno;
    munmap(p, mapped_);
    delete self_;
    delete host_;
    fail(ErrorCode::Internal, "could not protect a fiber stack's guard page: ", std::strerror(err));
  }
  stack_ = p;
}

Fiber::~Fiber() {
  munmap(stack_, mapped_);
  delete self_;
  delete host_;
}

void Fiber::start(std::function<void()> fn) {
  if (!finished_ && !fresh_) fail(ErrorCode::Internal, "Fiber::start: the fiber is inside its function");
  fn_ = std::move(fn);
  fresh_ = true;
  finished_ = false;
}

void Fiber::resume() {
  if (finished_) return;
  if (fresh_) {
    if (getcontext(&self_->uc) != 0) {
      fresh_ = false;  // never entered: finished, so that start() may use it again
      finished_ = true;
      fn_ = nullptr;
      fail(ErrorCode::Internal, "getcontext failed: ", std::strerror(errno));
    }
    self_->uc.uc_stack.ss_sp = static_cast<char*>(stack_) + (mapped_ - stackBytes_);
    self_->uc.uc_stack.ss_size = stackBytes_;
    self_->uc.uc_link = nullptr;  // entry() never returns: it switches back itself
    makecontext(&self_->uc, &Fiber::entry, 0);
    self_->eh = EhGlobals{};
    fresh_ = false;
    tEntering = this;
  }
  Fiber* outer = tRunning;
  tRunning = this;
  switchContext(*host_, *self_);
  tRunning = outer;
}

void Fiber::entry() {
  Fiber* f = tEntering;
  tEntering = nullptr;
  try {
    f->fn_();
  } catch (...) {
    // fn is the caller's wrapper, which catches everything itself; an exception cannot cross
    // into the thread that resumed the fiber.
    std::terminate();
  }
  f->fn_ = nullptr;
  f->finished_ = true;
  switchContext(*f->self_, *f->host_);
  std::abort();  // a finished fiber is never resumed
}

void Fiber::suspend() {
  Fiber* f = tRunning;
  if (!f) fail(ErrorCode::Internal, "Fiber::suspend outside a fiber");
  switchContext(*f->self_, *f->host_);
}

bool Fiber::inFiber() { return tRunning != nullptr; }

#else  // no ucontext, or AddressSanitizer: BatchGroup uses a thread per body

struct Fiber::Context {};
bool fibersAvailable() { return false; }
Fiber::Fiber(std::size_t) : self_(nullptr), host_(nullptr) { fail(ErrorCode::Internal, "fibers are not available in this build"); }
Fiber::~Fiber() = default;
void Fiber::start(std::function<void()>) {}
void Fiber::resume() {}
void Fiber::entry() {}
void Fiber::suspend() {}
bool Fiber::inFiber() { return false; }

#endif

}  // namespace corofem::detail
