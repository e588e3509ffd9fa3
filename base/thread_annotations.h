// Clang's thread-safety annotations, spelled as macros. Classes that share
// state across threads state their locking rules with these instead of
// comments ("guarded by mutex_"), so that clang checks the rules at compile
// time (-Wthread-safety; the test suite runs that check, docs/TESTING.md).
// Other compilers, gcc included, see the macros expand to nothing.
//
// The capability types to use them with are in base/mutex.h: libstdc++'s
// std::mutex carries no annotations of its own.
#pragma once

#if defined(__clang__)
#define OCTOCOSM_THREAD_ANNOTATION(x) __attribute__((x))
#else
#define OCTOCOSM_THREAD_ANNOTATION(x)
#endif

// On a class: its objects are capabilities (locks) of the kind named.
#define CAPABILITY(kind) OCTOCOSM_THREAD_ANNOTATION(capability(kind))
// On a class: RAII objects that hold a capability for their lifetime.
#define SCOPED_CAPABILITY OCTOCOSM_THREAD_ANNOTATION(scoped_lockable)

// On a data member: read or written only while the capability is held.
#define GUARDED_BY(x) OCTOCOSM_THREAD_ANNOTATION(guarded_by(x))
// On a pointer member: what it points to is read or written only under `x`.
#define PT_GUARDED_BY(x) OCTOCOSM_THREAD_ANNOTATION(pt_guarded_by(x))

// On a function: the caller must hold the capabilities (exclusively, or at
// least shared), or must not hold them (the function takes them itself).
#define REQUIRES(...) OCTOCOSM_THREAD_ANNOTATION(requires_capability(__VA_ARGS__))
#define REQUIRES_SHARED(...) OCTOCOSM_THREAD_ANNOTATION(requires_shared_capability(__VA_ARGS__))
#define EXCLUDES(...) OCTOCOSM_THREAD_ANNOTATION(locks_excluded(__VA_ARGS__))

// On a function: it takes or gives back the capabilities (none named: `this`).
#define ACQUIRE(...) OCTOCOSM_THREAD_ANNOTATION(acquire_capability(__VA_ARGS__))
#define ACQUIRE_SHARED(...) OCTOCOSM_THREAD_ANNOTATION(acquire_shared_capability(__VA_ARGS__))
#define RELEASE(...) OCTOCOSM_THREAD_ANNOTATION(release_capability(__VA_ARGS__))
#define RELEASE_SHARED(...) OCTOCOSM_THREAD_ANNOTATION(release_shared_capability(__VA_ARGS__))
// On a function: tells the analysis the capability is held from here on
// (checked at run time, if at all, by the function itself).
#define ASSERT_CAPABILITY(x) OCTOCOSM_THREAD_ANNOTATION(assert_capability(x))
// On a function: it returns a reference to the capability named.
#define RETURN_CAPABILITY(x) OCTOCOSM_THREAD_ANNOTATION(lock_returned(x))

// On a function: not checked. For code whose safety rests on something the
// analysis cannot see (a phase in which one thread owns the object); say why
// next to each use.
#define NO_THREAD_SAFETY_ANALYSIS OCTOCOSM_THREAD_ANNOTATION(no_thread_safety_analysis)
