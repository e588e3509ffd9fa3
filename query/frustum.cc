#include "query/frustum.h"

#include <cmath>
#include <numbers>
#include <string>

#include "base/error.h"

namespace octocosm {
namespace {

using Vec3 = std::array<double, 3>;

double Dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
Vec3 Scaled(const Vec3& a, double s) { return {a[0] * s, a[1] * s, a[2] * s}; }
Vec3 Sum(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
double Length(const Vec3& a) { return std::sqrt(Dot(a, a)); }
Vec3 Normalized(const Vec3& a) { return Scaled(a, 1 / Length(a)); }
bool Finite(const Vec3& a) { return std::isfinite(a[0]) && std::isfinite(a[1]) && std::isfinite(a[2]); }

Plane PlaneThrough(const Vec3& point, const Vec3& inward) {
  const Vec3 n = Normalized(inward);
  return Plane{n, -Dot(n, point)};
}

}  // namespace

Camera Camera::FromViewMatrix(const std::array<double, 16>& view, double fov_y_degrees, double aspect, double near,
                              double far) {
  // Column-major: element (row, col) is view[col * 4 + row]. The rows of the
  // rotation are the eye's right, up and backward axes in world coordinates.
  const Vec3 right{view[0], view[4], view[8]};
  const Vec3 up{view[1], view[5], view[9]};
  const Vec3 back{view[2], view[6], view[10]};
  const Vec3 translation{view[12], view[13], view[14]};
  for (double v : view) {
    if (!std::isfinite(v)) throw Error::InvalidArgument("view matrix: an element is not finite");
  }
  const double tolerance = 1e-6;
  if (std::fabs(Length(right) - 1) > tolerance || std::fabs(Length(up) - 1) > tolerance ||
      std::fabs(Length(back) - 1) > tolerance || std::fabs(Dot(right, up)) > tolerance ||
      std::fabs(Dot(right, back)) > tolerance || std::fabs(Dot(up, back)) > tolerance) {
    throw Error::InvalidArgument("view matrix: the rotation part is not orthonormal (a view matrix has no scaling)");
  }
  Camera camera;
  // eye = R * world + t, so the camera (eye origin) is at world = -R^T t.
  camera.position = Scaled(Sum(Sum(Scaled(right, translation[0]), Scaled(up, translation[1])), Scaled(back, translation[2])), -1);
  camera.look_at = Sum(camera.position, Scaled(back, -1));
  camera.up = up;
  camera.fov_y_degrees = fov_y_degrees;
  camera.aspect = aspect;
  camera.near = near;
  camera.far = far;
  camera.Validate();
  return camera;
}

void Camera::Validate() const {
  if (!Finite(position)) throw Error::InvalidArgument("camera position is not finite");
  if (!Finite(look_at)) throw Error::InvalidArgument("camera look-at point is not finite");
  if (!Finite(up)) throw Error::InvalidArgument("camera up vector is not finite");
  const Vec3 forward{look_at[0] - position[0], look_at[1] - position[1], look_at[2] - position[2]};
  if (Length(forward) == 0) throw Error::InvalidArgument("camera look-at point equals its position");
  if (Length(Cross(Normalized(forward), up)) < 1e-9 * Length(up)) {
    throw Error::InvalidArgument("camera up vector is zero or parallel to the viewing direction");
  }
  if (!(fov_y_degrees > 0 && fov_y_degrees < 180)) {
    throw Error::InvalidArgument("camera field of view must be in (0, 180) degrees, got " + std::to_string(fov_y_degrees));
  }
  if (!(aspect > 0 && std::isfinite(aspect))) throw Error::InvalidArgument("camera aspect ratio must be > 0");
  if (!(near > 0 && std::isfinite(near))) throw Error::InvalidArgument("camera near distance must be > 0");
  if (!(far > near)) throw Error::InvalidArgument("camera far distance must exceed the near distance");
}

std::array<double, 3> Camera::Forward() const {
  return Normalized({look_at[0] - position[0], look_at[1] - position[1], look_at[2] - position[2]});
}
std::array<double, 3> Camera::Right() const { return Normalized(Cross(Forward(), up)); }
std::array<double, 3> Camera::TrueUp() const { return Cross(Right(), Forward()); }

Frustum Frustum::FromCamera(const Camera& camera) {
  camera.Validate();
  const Vec3 f = camera.Forward(), r = camera.Right(), u = camera.TrueUp();
  const double tan_y = std::tan(camera.fov_y_degrees * std::numbers::pi / 360);
  const double tan_x = tan_y * camera.aspect;
  // A direction f + a r + b u is inside the side planes when |a| <= tan_x and
  // |b| <= tan_y; (tan_x f + r) . (f + a r) = tan_x + a >= 0 is the left plane.
  Frustum frustum;
  frustum.planes_ = {
      PlaneThrough(Sum(camera.position, Scaled(f, camera.near)), f),
      PlaneThrough(Sum(camera.position, Scaled(f, camera.far)), Scaled(f, -1)),
      PlaneThrough(camera.position, Sum(Scaled(f, tan_x), r)),
      PlaneThrough(camera.position, Sum(Scaled(f, tan_x), Scaled(r, -1))),
      PlaneThrough(camera.position, Sum(Scaled(f, tan_y), u)),
      PlaneThrough(camera.position, Sum(Scaled(f, tan_y), Scaled(u, -1))),
  };
  return frustum;
}

Frustum Frustum::FromPlanes(const std::array<Plane, 6>& planes) {
  Frustum frustum;
  for (std::size_t i = 0; i < planes.size(); ++i) {
    const double length = Length(planes[i].normal);
    if (!Finite(planes[i].normal) || !std::isfinite(planes[i].offset) || !(length > 0)) {
      throw Error::InvalidArgument("frustum plane " + std::to_string(i + 1) + " has a zero or non-finite normal or offset");
    }
    frustum.planes_[i] = Plane{Scaled(planes[i].normal, 1 / length), planes[i].offset / length};
  }
  return frustum;
}

bool Frustum::Contains(const double* p) const {
  for (const Plane& plane : planes_) {
    if (plane.SignedDistance(p) < 0) return false;
  }
  return true;
}

bool Frustum::MayIntersectBox(const std::array<double, 3>& lo, const std::array<double, 3>& hi) const {
  for (const Plane& plane : planes_) {
    double farthest[3];
    for (int a = 0; a < 3; ++a) farthest[a] = plane.normal[a] >= 0 ? hi[a] : lo[a];
    // A little slack so that rounding never culls a box that touches the plane.
    const double slack = 1e-12 * (std::fabs(farthest[0]) + std::fabs(farthest[1]) + std::fabs(farthest[2]) + std::fabs(plane.offset));
    if (plane.SignedDistance(farthest) < -slack) return false;
  }
  return true;
}

bool Frustum::ContainsBox(const std::array<double, 3>& lo, const std::array<double, 3>& hi) const {
  for (const Plane& plane : planes_) {
    double nearest[3];
    for (int a = 0; a < 3; ++a) nearest[a] = plane.normal[a] >= 0 ? lo[a] : hi[a];
    if (!(plane.SignedDistance(nearest) >= 0)) return false;
  }
  return true;
}

}  // namespace octocosm
