// Fibers: stackful coroutines that a thread runs in turns (glibc's ucontext), for the drivers of a
// batch's bodies (solve/batch_group.cpp). A body's step is ordinary blocking code that meets the
// other bodies in rounds; as a fiber it gives its thread to the next body where a thread per body
// would sleep in the kernel and be woken by it (about 0.26 ms a round for 100 bodies on 2 cores,
// most of it context switches).
//
// Each context (the thread's own and each fiber's) keeps its own C++ exception-handling globals (the
// stack of exceptions being caught and the count of uncaught ones), swapped at every switch: a fiber
// may suspend inside a catch block while another fiber of the same thread throws and catches, and a
// `throw;` there still rethrows its own exception.
#pragma once

#include <cstddef>
#include <functional>

namespace corofem::detail {

/// Whether fibers can run in this build: glibc's ucontext, and not under AddressSanitizer (its
/// fake stacks would need an annotation at every switch). Where false, BatchGroup gives each body a
/// thread of its own.
bool fibersAvailable();

class Fiber {
 public:
  /// A fiber with a stack of `stackBytes` (reserved, not committed: pages are touched as they are
  /// used) and a guard page below it. Throws Error(Internal) when the stack cannot be mapped.
  explicit Fiber(std::size_t stackBytes);
  ~Fiber();
  Fiber(const Fiber&) = delete;
  Fiber& operator=(const Fiber&) = delete;

  /// Makes the fiber run `fn` from its beginning at the next resume(). Not while it is running or
  /// suspended inside a previous fn (finished() or never started).
  void start(std::function<void()> fn);
  /// Runs the fiber on the calling thread until fn returns (finished()) or calls suspend(). A
  /// suspended fiber is resumed by the same thread only. Throws Error(Internal), leaving the fiber
  /// finished without having run fn, where a fresh fiber's context cannot be made.
  void resume();
  bool finished() const { return finished_; }

  /// From inside a fiber: back to the resume() that ran it.
  static void suspend();
  /// Whether the caller runs inside a fiber.
  static bool inFiber();

  struct Context;  ///< a saved context and its exception globals (fiber.cpp)

 private:
  static void entry();
  Context* self_;
  Context* host_;
  void* stack_ = nullptr;
  std::size_t mapped_ = 0;
  std::size_t stackBytes_ = 0;
  std::function<void()> fn_;
  bool fresh_ = false;     ///< start() called, not yet entered
  bool finished_ = true;
};

}  // namespace corofem::detail
