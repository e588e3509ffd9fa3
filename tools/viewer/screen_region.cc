#include "tools/viewer/screen_region.h"

#include <array>
#include <string>

#include "base/error.h"

namespace octocosm {
namespace {

// The plane a . (p - origin) >= 0 with a = s * side + t * forward.
Plane PlaneThroughCamera(const std::array<double, 3>& origin, const std::array<double, 3>& side, double s,
                         const std::array<double, 3>& forward, double t) {
  Plane plane;
  for (int a = 0; a < 3; ++a) plane.normal[a] = s * side[a] + t * forward[a];
  plane.offset = -(plane.normal[0] * origin[0] + plane.normal[1] * origin[1] + plane.normal[2] * origin[2]);
  return plane;
}

}  // namespace

Frustum RectangleFrustum(const RenderView& view, const ScreenRectangle& r) {
  if (!(r.x0 < r.x1 && r.y0 < r.y1)) {
    throw Error::InvalidArgument("a selection rectangle needs a width and a height (got " + std::to_string(r.width()) +
                                 " x " + std::to_string(r.height()) + " pixels)");
  }
  // In eye coordinates (x, y, depth) a point lands at window x = w/2 + f x / depth,
  // so x >= x0 there is  f x + (w/2 - x0) depth >= 0: a plane through the camera.
  const Camera& c = view.camera();
  const double f = view.focal_pixels();
  const double cx = view.width() / 2.0, cy = view.height() / 2.0;
  const auto& right = view.right();
  const auto& up = view.up();
  const auto& forward = view.forward();
  Plane near = PlaneThroughCamera(c.position, forward, 1, forward, 0);
  near.offset -= c.near;
  Plane far = PlaneThroughCamera(c.position, forward, -1, forward, 0);
  far.offset += c.far;
  return Frustum::FromPlanes({
      near,
      far,
      PlaneThroughCamera(c.position, right, f, forward, cx - r.x0),   // left
      PlaneThroughCamera(c.position, right, -f, forward, r.x1 - cx),  // right
      PlaneThroughCamera(c.position, up, f, forward, cy - r.y0),      // bottom
      PlaneThroughCamera(c.position, up, -f, forward, r.y1 - cy),     // top
  });
}

}  // namespace octocosm
