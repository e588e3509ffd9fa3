// Cameras and view frusta: the six planes of what a perspective camera sees,
// and the conservative box test that culls octree nodes against them.
//
// A camera is a position, a look-at point and an up direction (or an OpenGL
// view matrix), a vertical field of view, an aspect ratio (width / height) and
// near and far distances along the viewing direction. Its frustum is the set
// of points p with  near <= (p - position) . forward <= far  and inside the
// four side planes through the camera position that the field of view spans.
// Planes are stored with unit normals pointing inward: p is inside a plane
// when normal . p + offset >= 0.
#pragma once

#include <array>

namespace octocosm {

struct Camera {
  std::array<double, 3> position{0, 0, 0};
  std::array<double, 3> look_at{0, 0, -1};
  std::array<double, 3> up{0, 1, 0};
  double fov_y_degrees = 60;  // vertical field of view, (0, 180)
  double aspect = 1;          // viewport width / height, > 0
  double near = 1e-3;         // > 0
  double far = 1e30;          // > near

  // The camera of an OpenGL (glm) view matrix, column-major: the world-to-eye
  // transform whose eye looks down -z with +y up. The rotation part must be
  // orthonormal (to 1e-6); throws Error::InvalidArgument otherwise.
  static Camera FromViewMatrix(const std::array<double, 16>& view, double fov_y_degrees, double aspect, double near,
                               double far);

  // Throws Error::InvalidArgument naming the first unusable value: non-finite
  // numbers, look_at == position, up parallel to the viewing direction, or a
  // field of view, aspect or near/far range out of its bounds above.
  void Validate() const;
  // Unit vectors: the viewing direction, the right-hand side, the true up.
  std::array<double, 3> Forward() const;
  std::array<double, 3> Right() const;
  std::array<double, 3> TrueUp() const;
};

struct Plane {
  std::array<double, 3> normal{0, 0, 1};  // unit length, pointing inward
  double offset = 0;
  double SignedDistance(const double* p) const { return normal[0] * p[0] + normal[1] * p[1] + normal[2] * p[2] + offset; }
};

class Frustum {
 public:
  // Order: near, far, left, right, bottom, top. Validates the camera.
  static Frustum FromCamera(const Camera& camera);
  // Any six (or fewer, repeated) planes, inward normals; they are normalized.
  // Throws Error::InvalidArgument for a zero or non-finite normal or offset.
  static Frustum FromPlanes(const std::array<Plane, 6>& planes);

  const std::array<Plane, 6>& planes() const { return planes_; }
  bool Contains(const double* p) const;
  // False only when the box [lo, hi] lies entirely outside one plane (the
  // classic "positive vertex" test): it may answer true for a box outside the
  // frustum near an edge, never false for a box that meets it.
  bool MayIntersectBox(const std::array<double, 3>& lo, const std::array<double, 3>& hi) const;
  // True only when the box [lo, hi] lies entirely inside every plane.
  bool ContainsBox(const std::array<double, 3>& lo, const std::array<double, 3>& hi) const;

 private:
  std::array<Plane, 6> planes_{};
};

}  // namespace octocosm
