// x_input_driver: plays mouse and keyboard input into an X display through
// the XTEST extension, as a user would, for the viewer's test
// (view_test.cc). XTEST events are real input to the X server, so GLFW (and
// Dear ImGui behind it) sees them exactly like a hand on the mouse.
//
//   x_input_driver STEP...
//
//   wait-text FILE TEXT SECONDS  until FILE holds TEXT (the viewer's stderr
//                                says what it has done: a script's screenshot,
//                                a selection, a P screenshot)
//   wait-window PREFIX SECONDS   until a window whose name starts with PREFIX
//                                exists; the following steps act on it
//   move X Y                     pointer to (X, Y) in the window (pixels, y down)
//   drag X0 Y0 X1 Y1             left button down at (X0, Y0), moved in steps
//                                to (X1, Y1), up
//   key-down NAME, key-up NAME   a key by its X keysym name (p, w, Shift_L, ...)
//   tap NAME                     a key pressed and released
//   sleep MS
//   close                        asks the window to close (WM_DELETE_WINDOW)
//
// Every wait has its limit. Exits 0 when every step worked; otherwise says
// which step failed, asks the window to close (so that the viewer does not
// wait for input for ever) and exits 1.
#include <X11/Xlib.h>
#include <X11/Xutil.h>
#include <X11/extensions/XTest.h>

#include <charconv>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace {

// A step that cannot be done: main reports it and ends the run.
struct StepFailed : std::runtime_error {
  using std::runtime_error::runtime_error;
};

void Sleep(int milliseconds) { std::this_thread::sleep_for(std::chrono::milliseconds(milliseconds)); }

template <typename Done>
bool WaitFor(double seconds, const Done& done) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (!done()) {
    if (std::chrono::steady_clock::now() > until) return false;
    Sleep(50);
  }
  return true;
}

// Windows come and go while the tree is walked (GLFW's hidden helper
// window, the viewer closing): a request about one that has gone is not
// the end of the run, as Xlib's default handler would make it.
int IgnoreXError(Display*, XErrorEvent*) { return 0; }

bool FileHolds(const std::string& path, const std::string& text) {
  std::ifstream in(path);
  std::stringstream contents;
  contents << in.rdbuf();
  return contents.str().find(text) != std::string::npos;
}

class Driver {
 public:
  Driver() : display_(XOpenDisplay(nullptr)) {
    if (!display_) throw StepFailed("cannot open the display (is DISPLAY set?)");
    XSetErrorHandler(IgnoreXError);
    int event_base, error_base, major, minor;
    if (!XTestQueryExtension(display_, &event_base, &error_base, &major, &minor)) {
      XCloseDisplay(display_);
      throw StepFailed("the X server has no XTEST extension");
    }
  }
  ~Driver() { XCloseDisplay(display_); }
  Driver(const Driver&) = delete;
  Driver& operator=(const Driver&) = delete;

  void Run(const std::vector<std::string>& steps);
  // Asks the window, if one was found, to close.
  void Close();

 private:
  const std::string& Next(const char* step);
  int Number(const char* step);
  double Seconds(const char* step);
  Window FindWindow(Window under, const std::string& prefix);
  void MovePointer(int x, int y);
  void Key(const std::string& name, bool down);

  Display* display_;
  Window window_ = 0;
  const std::vector<std::string>* steps_ = nullptr;
  std::size_t next_ = 0;
};

const std::string& Driver::Next(const char* step) {
  if (next_ >= steps_->size()) throw StepFailed(std::string(step) + ": an argument is missing");
  return (*steps_)[next_++];
}

int Driver::Number(const char* step) {
  const std::string& text = Next(step);
  int value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size()) {
    throw StepFailed(std::string(step) + ": '" + text + "' is not a whole number");
  }
  return value;
}

double Driver::Seconds(const char* step) {
  const int seconds = Number(step);
  if (seconds <= 0) throw StepFailed(std::string(step) + ": the time limit must be > 0 seconds");
  return seconds;
}

Window Driver::FindWindow(Window under, const std::string& prefix) {
  char* name = nullptr;
  if (XFetchName(display_, under, &name) && name) {
    const bool match = std::strncmp(name, prefix.c_str(), prefix.size()) == 0;
    XFree(name);
    if (match) return under;
  }
  Window root, parent, *children = nullptr;
  unsigned count = 0;
  Window found = 0;
  if (XQueryTree(display_, under, &root, &parent, &children, &count)) {
    for (unsigned i = 0; i < count && !found; ++i) found = FindWindow(children[i], prefix);
    if (children) XFree(children);
  }
  return found;
}

void Driver::MovePointer(int x, int y) {
  int root_x = 0, root_y = 0;
  Window child;
  XTranslateCoordinates(display_, window_, DefaultRootWindow(display_), x, y, &root_x, &root_y, &child);
  XTestFakeMotionEvent(display_, -1, root_x, root_y, CurrentTime);
  XFlush(display_);
}

void Driver::Key(const std::string& name, bool down) {
  const KeySym sym = XStringToKeysym(name.c_str());
  const KeyCode code = sym == NoSymbol ? 0 : XKeysymToKeycode(display_, sym);
  if (code == 0) throw StepFailed("no key named " + name);
  XTestFakeKeyEvent(display_, code, down ? True : False, CurrentTime);
  XFlush(display_);
}

void Driver::Close() {
  if (!window_) return;
  XEvent event{};
  event.xclient.type = ClientMessage;
  event.xclient.window = window_;
  event.xclient.message_type = XInternAtom(display_, "WM_PROTOCOLS", False);
  event.xclient.format = 32;
  event.xclient.data.l[0] = static_cast<long>(XInternAtom(display_, "WM_DELETE_WINDOW", False));
  event.xclient.data.l[1] = CurrentTime;
  XSendEvent(display_, window_, False, NoEventMask, &event);
  XFlush(display_);
}

void Driver::Run(const std::vector<std::string>& steps) {
  steps_ = &steps;
  while (next_ < steps.size()) {
    const std::string& step = steps[next_++];
    const bool needs_window = step != "wait-text" && step != "wait-window" && step != "sleep";
    if (needs_window && !window_) throw StepFailed(step + " before wait-window");
    if (step == "wait-text") {
      const std::string path = Next("wait-text"), text = Next("wait-text");
      const double seconds = Seconds("wait-text");
      if (!WaitFor(seconds, [&] { return FileHolds(path, text); })) {
        throw StepFailed("no '" + text + "' in " + path + " after " + std::to_string(seconds) + " s");
      }
    } else if (step == "wait-window") {
      const std::string prefix = Next("wait-window");
      const double seconds = Seconds("wait-window");
      if (!WaitFor(seconds, [&] { return (window_ = FindWindow(DefaultRootWindow(display_), prefix)) != 0; })) {
        throw StepFailed("no window named " + prefix + "... after " + std::to_string(seconds) + " s");
      }
      // No window manager under Xvfb: give the window the keyboard.
      XSetInputFocus(display_, window_, RevertToParent, CurrentTime);
      XFlush(display_);
    } else if (step == "move") {
      const int x = Number("move"), y = Number("move");
      MovePointer(x, y);
    } else if (step == "drag") {
      const int x0 = Number("drag"), y0 = Number("drag"), x1 = Number("drag"), y1 = Number("drag");
      MovePointer(x0, y0);
      Sleep(100);
      XTestFakeButtonEvent(display_, 1, True, CurrentTime);
      XFlush(display_);
      constexpr int kSteps = 10;
      for (int k = 1; k <= kSteps; ++k) {
        Sleep(40);
        MovePointer(x0 + (x1 - x0) * k / kSteps, y0 + (y1 - y0) * k / kSteps);
      }
      Sleep(100);
      XTestFakeButtonEvent(display_, 1, False, CurrentTime);
      XFlush(display_);
    } else if (step == "key-down" || step == "key-up") {
      Key(Next(step.c_str()), step == "key-down");
    } else if (step == "tap") {
      const std::string& name = Next("tap");
      Key(name, true);
      Sleep(100);
      Key(name, false);
    } else if (step == "sleep") {
      Sleep(Number("sleep"));
    } else if (step == "close") {
      Close();
    } else {
      throw StepFailed("unknown step '" + step + "'");
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<std::string> steps(argv + 1, argv + argc);
  try {
    Driver driver;
    try {
      driver.Run(steps);
    } catch (const StepFailed&) {
      driver.Close();
      throw;
    }
  } catch (const StepFailed& failure) {
    std::fprintf(stderr, "x_input_driver: %s\n", failure.what());
    return 1;
  }
  return 0;
}
