// Box selection in the viewer: the part of the view frustum that lies under a
// rectangle drawn on the screen, as six planes that query/region.h
// (MakeFrustumRegion) turns into a query region.
#pragma once

#include "query/frustum.h"
#include "render/render_view.h"

namespace octocosm {

// In the window coordinates of render/render_view.h: pixels, origin at the
// lower-left corner, y up.
struct ScreenRectangle {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // x0 < x1, y0 < y1

  double width() const { return x1 - x0; }
  double height() const { return y1 - y0; }
};

// The points that `view` projects into the rectangle, between its near and
// far planes: a point p is inside when RenderView::Project(p) succeeds and
// lands in [x0, x1] x [y0, y1]. Throws Error::InvalidArgument for an empty
// rectangle.
Frustum RectangleFrustum(const RenderView& view, const ScreenRectangle& rectangle);

}  // namespace octocosm
