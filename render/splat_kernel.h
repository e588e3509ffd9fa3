// How one point becomes a blob of pixels: the kernel of the renderer, stated
// once for both rasterizers (the GPU's shaders/splat.*.glsl and the CPU's
// reference_rasterizer.h), which tests hold to each other.
//
// A point of weight w (the mass it stands for) and smoothing length h, at
// depth z in front of the camera, is a disc of radius
//
//     R = clamp(h * f / z, 1, R_max)   pixels     (f: focal length in pixels)
//
// centred on its projection c (window coordinates: pixel (i, j) has its centre
// at (i + 1/2, j + 1/2)). Pixel p receives
//
//     w * W(|p - c| / R) / N(c, R)
//
// with W the two-dimensional cubic spline (M4) kernel
//
//     W(q) = 1 - 6 q^2 + 6 q^3   for 0 <= q < 1/2
//            2 (1 - q)^3          for 1/2 <= q < 1
//            0                    for q >= 1
//
// and N the normalization that makes the pixels of the blob sum to w:
//
//     N = sum over all pixels p of W(|p - c| / R)   when R < kExactNormalizationRadius
//     N = (7 pi / 40) R^2   (the integral of W)     otherwise.
//
// Why the exact sum below 4 px: at R = 1 the integral misjudges the sum by
// up to 82% depending on where c falls in its pixel, so small blobs would
// gain or lose mass; from R = 4 on the integral is within 4.1e-4 of the sum
// (the worst over random centres; 2.7e-5 from R = 6), so the image conserves
// each point's weight to that relative error (to rounding below 4 px).
// R >= 1 guarantees N > 0: every point lies within sqrt(2)/2 of a pixel
// centre. R_max bounds the cost of one blob and is what a GL point can cover:
// the GPU draws a point sprite of side 2 R + kSpriteGuard pixels (GL shades
// the pixels whose centres lie in the sprite's square; the guard covers the
// rasterizer's sub-pixel rounding of the centre, 1/256 pixel on common
// hardware), and GL guarantees sprites only up to an implementation limit
// (255 pixels on llvmpipe). The square is tight: a 1-pixel blob shades at
// most 4 pixels, not the 9 of a sprite rounded up to whole pixels.
#pragma once

namespace octocosm {

inline constexpr double kMinBlobRadius = 1;             // pixels
inline constexpr double kDefaultMaxBlobRadius = 127;    // pixels: a 255-pixel sprite
inline constexpr double kExactNormalizationRadius = 4;  // pixels
inline constexpr double kSpriteGuard = 1.0 / 16;         // pixels
inline constexpr double kKernelIntegral = 0.54977871437821381673;  // 7 pi / 40: integral of W over the unit disc

// W(q) above.
double CubicKernel(double q);

// The blob radius in pixels for smoothing length h at depth z (> 0), focal
// length f in pixels.
double BlobRadius(double smoothing, double focal_pixels, double depth, double max_radius);

// N(c, R) above, for a centre (cx, cy) in window coordinates and R >= 1.
double KernelNormalization(double cx, double cy, double radius);

// The sum of W over pixel centres, the exact N (any R > 0).
double KernelPixelSum(double cx, double cy, double radius);

// Pixels of border the GPU renders around the image so that blobs centred
// just outside it still reach in (GL discards points whose centre is outside
// the viewport): at least the largest radius.
int GuardMargin(double max_radius);

// The side of the GL point sprite that covers a blob of radius R.
double SpriteSize(double radius);

}  // namespace octocosm
