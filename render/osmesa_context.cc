// The OSMesa backend of CreateHeadlessContext: Mesa's software rasterizer.
// libOSMesa is loaded when first asked for, not linked: it brings LLVM with
// it, and a machine that renders through EGL on a GPU need not have it.
#include <GL/osmesa.h>
#include <dlfcn.h>
#include <signal.h>
#include <unistd.h>

#include <array>
#include <string>

#include "base/error.h"
#include "base/mutex.h"
#include "render/gl_context.h"

namespace octocosm {
namespace {

struct OsMesaLibrary {
  decltype(&OSMesaCreateContextAttribs) create = nullptr;
  decltype(&OSMesaMakeCurrent) make_current = nullptr;
  decltype(&OSMesaDestroyContext) destroy = nullptr;
  decltype(&OSMesaGetProcAddress) get_proc_address = nullptr;
};

// What dlopen says when the file is not there at all.
bool IsMissingFile(const std::string& why) { return why.find("No such file or directory") != std::string::npos; }

const OsMesaLibrary& LoadOsMesa() {
  static const OsMesaLibrary library = [] {
    // Each name's own error: dlerror() keeps only the last, and the first
    // name (the library as installed) is the one whose failure explains.
    std::string errors;
    void* handle = nullptr;
    bool all_missing = true;
    for (const char* name : {"libOSMesa.so.8", "libOSMesa.so"}) {
      handle = dlopen(name, RTLD_NOW | RTLD_LOCAL);
      if (handle != nullptr) break;
      const char* why = dlerror();
      const std::string text = why ? why : std::string(name) + ": not found";
      all_missing = all_missing && IsMissingFile(text) && text.rfind(name, 0) == 0;
      if (errors.find(text) == std::string::npos) errors += (errors.empty() ? "" : "; ") + text;
    }
    if (handle == nullptr) {
      if (all_missing) {
        throw Error::NotSupported("OSMesa", "libOSMesa is not installed (install libosmesa6, or use --backend egl on "
                                            "a GPU): " + errors);
      }
      // There, but it or a library it needs would not load: out of memory
      // (a ulimit -v), a missing dependency, a broken installation.
      const bool memory = errors.find("failed to map segment") != std::string::npos ||
                          errors.find("Cannot allocate memory") != std::string::npos;
      throw Error::NotSupported("OSMesa", "libOSMesa could not be loaded: " + errors +
                                              (memory ? " (out of memory: a memory limit such as ulimit -v?)" : ""));
    }
    OsMesaLibrary l;
    l.create = reinterpret_cast<decltype(l.create)>(dlsym(handle, "OSMesaCreateContextAttribs"));
    l.make_current = reinterpret_cast<decltype(l.make_current)>(dlsym(handle, "OSMesaMakeCurrent"));
    l.destroy = reinterpret_cast<decltype(l.destroy)>(dlsym(handle, "OSMesaDestroyContext"));
    l.get_proc_address = reinterpret_cast<decltype(l.get_proc_address)>(dlsym(handle, "OSMesaGetProcAddress"));
    if (!l.create || !l.make_current || !l.destroy || !l.get_proc_address) {
      throw Error::NotSupported("OSMesa", "libOSMesa lacks OSMesaCreateContextAttribs (Mesa 11 or later is needed)");
    }
    return l;  // never unloaded: contexts may outlive any one caller
  }();
  return library;
}

// Mesa does not check every allocation: when memory runs out (under a
// ulimit -v, say) it can crash, in OSMesaCreateContextAttribs or in any GL
// call after it (a shader compile), instead of reporting an error. A crash
// cannot become an error, but it can say what it most likely was. While a
// context lives, SIGSEGV and SIGBUS print that note (with write(2) only, as
// a signal handler may) and then go to the handler that was there before
// (AddressSanitizer's, in its builds) or take their default action.
class CrashNote {
 public:
  CrashNote() {
    MutexLock lock(mutex_);
    if (users_++ > 0) return;
    struct sigaction action {};
    action.sa_sigaction = &Note;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_SIGINFO | SA_ONSTACK;  // an alternate stack where one is set (AddressSanitizer sets one)
    sigaction(SIGSEGV, &action, &previous_segv_);
    sigaction(SIGBUS, &action, &previous_bus_);
  }
  ~CrashNote() {
    MutexLock lock(mutex_);
    if (--users_ > 0) return;
    sigaction(SIGSEGV, &previous_segv_, nullptr);
    sigaction(SIGBUS, &previous_bus_, nullptr);
  }
  CrashNote(const CrashNote&) = delete;
  CrashNote& operator=(const CrashNote&) = delete;

 private:
  static void Note(int signal_number, siginfo_t* info, void* context) {
    static constexpr char kNote[] =
        "octocosm: crashed while an OSMesa (software OpenGL) context was in use; Mesa crashes this way when "
        "memory runs out (a memory limit such as ulimit -v?)\n";
    [[maybe_unused]] const ssize_t ignored = ::write(STDERR_FILENO, kNote, sizeof kNote - 1);
    const struct sigaction& previous = signal_number == SIGBUS ? previous_bus_ : previous_segv_;
    if ((previous.sa_flags & SA_SIGINFO) != 0 && previous.sa_sigaction != nullptr) {
      previous.sa_sigaction(signal_number, info, context);
      return;
    }
    if (previous.sa_handler != SIG_DFL && previous.sa_handler != SIG_IGN && previous.sa_handler != nullptr) {
      previous.sa_handler(signal_number);
      return;
    }
    // Returning re-runs the faulting instruction, which now meets the default action.
    signal(signal_number, SIG_DFL);
  }

  static inline Mutex mutex_;
  static inline int users_ GUARDED_BY(mutex_) = 0;
  // Written under mutex_, read by the signal handler, which may not lock.
  static inline struct sigaction previous_segv_ {};
  static inline struct sigaction previous_bus_ {};
};

class OsMesaContext final : public GlContext {
 public:
  OsMesaContext() : library_(LoadOsMesa()) {
    const int attributes[] = {OSMESA_FORMAT,         OSMESA_RGBA,          OSMESA_DEPTH_BITS,          0,
                              OSMESA_STENCIL_BITS,   0,                    OSMESA_ACCUM_BITS,          0,
                              OSMESA_PROFILE,        OSMESA_CORE_PROFILE,  OSMESA_CONTEXT_MAJOR_VERSION, 4,
                              OSMESA_CONTEXT_MINOR_VERSION, 5,             0};
    context_ = library_.create(attributes, nullptr);
    if (context_ == nullptr) {
      throw Error::NotSupported("OSMesa", "could not create an OpenGL 4.5 core context: OSMesaCreateContextAttribs "
                                          "failed (it needs Mesa 20 or later, and memory: a memory limit?)");
    }
    MakeCurrent();
    // Through a local function: a GlProcLoader is a plain function pointer.
    static const OsMesaLibrary* loader = &library_;
    LoadGlFunctions([](const char* name) { return reinterpret_cast<void (*)()>(loader->get_proc_address(name)); },
                    "OSMesa");
  }
  ~OsMesaContext() override { library_.destroy(context_); }

  void MakeCurrent() override {
    // The renderer draws into framebuffer objects; OSMesa still wants a
    // buffer for the default framebuffer, so it gets a one-pixel one.
    if (!library_.make_current(context_, pixel_.data(), GL_UNSIGNED_BYTE, 1, 1)) {
      throw Error::NotSupported("OSMesa", "could not make the context current: OSMesaMakeCurrent failed (out of "
                                          "memory?)");
    }
  }

 private:
  const OsMesaLibrary& library_;
  const CrashNote crash_note_;  // before the context: lives longer than it
  OSMesaContext context_ = nullptr;
  std::array<unsigned char, 4> pixel_{};
};

}  // namespace

std::unique_ptr<GlContext> CreateOsMesaContext() { return std::make_unique<OsMesaContext>(); }

#ifndef OCTOCOSM_HAVE_EGL
std::unique_ptr<GlContext> CreateEglContext() {
  throw Error::NotSupported("EGL", "this build has no EGL support (install libegl-dev and rebuild)");
}
#endif

}  // namespace octocosm
