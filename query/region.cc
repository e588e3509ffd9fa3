#include "query/region.h"

#include <algorithm>
#include <cmath>

#include "base/error.h"

namespace octocosm {
namespace {

// a mod period in [0, period).
double PositiveMod(double a, double period) {
  const double m = a - std::floor(a / period) * period;
  if (m < 0) return 0;
  return m >= period ? std::nextafter(period, 0.0) : m;
}

// Node tests get a relative slack so that rounding never culls a node whose
// points Contains would keep (node cubes and points come from different
// arithmetic).
double Slack(const Cube& cube) { return 1e-9 * cube.size; }

class BoxRegion final : public Region {
 public:
  BoxRegion(const std::array<double, 3>& lo, const std::array<double, 3>& hi, const Cube& cube)
      : lo_(lo), hi_(hi), period_(cube.size), periodic_(cube.periodic), slack_(Slack(cube)) {}

  bool Contains(const double* p) const override {
    for (int a = 0; a < 3; ++a) {
      if (periodic_) {
        const double width = hi_[a] - lo_[a];
        if (width < period_ && PositiveMod(p[a] - lo_[a], period_) > width) return false;
      } else if (p[a] < lo_[a] || p[a] > hi_[a]) {
        return false;
      }
    }
    return true;
  }

  bool MayIntersect(const NodeCube& node) const override {
    for (int a = 0; a < 3; ++a) {
      const double start = node.origin[a], end = node.origin[a] + node.size;
      if (periodic_) {
        const double width = hi_[a] - lo_[a];
        if (width + node.size + 2 * slack_ >= period_) continue;
        // The image of the box that starts at or below `start`: the node meets
        // it when it starts inside it, or meets the next image up.
        const double d = PositiveMod(start - lo_[a], period_);
        if (d > width + slack_ && d + node.size < period_ - slack_) return false;
      } else if (start > hi_[a] + slack_ || end < lo_[a] - slack_) {
        return false;
      }
    }
    return true;
  }

 private:
  std::array<double, 3> lo_, hi_;
  double period_;
  bool periodic_;
  double slack_;
};

class SphereRegion final : public Region {
 public:
  SphereRegion(const std::array<double, 3>& center, double radius, const Cube& cube)
      : center_(center), radius_(radius), period_(cube.size), periodic_(cube.periodic), slack_(Slack(cube)) {}

  bool Contains(const double* p) const override {
    double distance2 = 0;
    for (int a = 0; a < 3; ++a) {
      double d = p[a] - center_[a];
      if (periodic_) d = PositiveMod(d + period_ / 2, period_) - period_ / 2;
      distance2 += d * d;
    }
    return distance2 <= radius_ * radius_;
  }

  bool MayIntersect(const NodeCube& node) const override {
    double distance2 = 0;
    for (int a = 0; a < 3; ++a) {
      double d;
      if (periodic_) {
        // Distance from the centre to the nearest image of [start, end].
        const double above = PositiveMod(center_[a] - node.origin[a], period_);
        d = above <= node.size ? 0 : std::min(above - node.size, period_ - above);
      } else {
        d = std::max({node.origin[a] - center_[a], 0.0, center_[a] - (node.origin[a] + node.size)});
      }
      d = std::max(d - slack_, 0.0);
      distance2 += d * d;
    }
    return distance2 <= radius_ * radius_;
  }

 private:
  std::array<double, 3> center_;
  double radius_;
  double period_;
  bool periodic_;
  double slack_;
};

class FrustumRegion final : public Region {
 public:
  explicit FrustumRegion(const Frustum& frustum) : frustum_(frustum) {}
  bool Contains(const double* p) const override { return frustum_.Contains(p); }
  bool MayIntersect(const NodeCube& node) const override {
    return frustum_.MayIntersectBox(node.origin, {node.origin[0] + node.size, node.origin[1] + node.size,
                                                  node.origin[2] + node.size});
  }

 private:
  Frustum frustum_;
};

class EverythingRegion final : public Region {
 public:
  bool Contains(const double*) const override { return true; }
  bool MayIntersect(const NodeCube&) const override { return true; }
};

}  // namespace

std::unique_ptr<Region> MakeBoxRegion(const std::array<double, 3>& lo, const std::array<double, 3>& hi, const Cube& cube) {
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(lo[a]) || !std::isfinite(hi[a])) throw Error::InvalidArgument("query box: a bound is not finite");
    if (lo[a] > hi[a]) throw Error::InvalidArgument("query box: lower corner exceeds upper corner on axis " + std::string(1, "xyz"[a]));
  }
  return std::make_unique<BoxRegion>(lo, hi, cube);
}

std::unique_ptr<Region> MakeSphereRegion(const std::array<double, 3>& center, double radius, const Cube& cube) {
  for (double c : center) {
    if (!std::isfinite(c)) throw Error::InvalidArgument("query sphere: the centre is not finite");
  }
  if (!(radius >= 0) || !std::isfinite(radius)) throw Error::InvalidArgument("query sphere: the radius must be finite and >= 0");
  return std::make_unique<SphereRegion>(center, radius, cube);
}

std::unique_ptr<Region> MakeFrustumRegion(const Frustum& frustum) { return std::make_unique<FrustumRegion>(frustum); }

std::unique_ptr<Region> MakeEverythingRegion() { return std::make_unique<EverythingRegion>(); }

}  // namespace octocosm
