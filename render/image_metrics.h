// How far a picture is from another: PSNR and SSIM of tone-mapped images,
// the measures the render benchmark and tests judge levels of detail by.
#pragma once

#include "render/image.h"

namespace octocosm {

// Peak signal-to-noise ratio over all three channels, values in [0, 1]:
// 10 log10(1 / mean squared error); 200 dB for identical images. Throws
// Error::InvalidArgument for images of different sizes.
double Psnr(const DisplayImage& a, const DisplayImage& b);

// Structural similarity (Z. Wang, A. C. Bovik, H. R. Sheikh, E. P. Simoncelli,
// "Image quality assessment: from error visibility to structural similarity",
// IEEE Trans. Image Processing 13(4), 2004) of the luminance (Rec. 709
// weights), with the paper's constants: an 11x11 Gaussian window of sigma 1.5,
// K1 = 0.01, K2 = 0.03, dynamic range 1; the mean over every pixel whose
// window fits the image. 1 for identical images.
double Ssim(const DisplayImage& a, const DisplayImage& b);

}  // namespace octocosm
