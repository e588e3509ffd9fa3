#!/usr/bin/env python3
"""Where a level of detail's error lies in a picture.

Reads the reference's and the frames' accumulations that
`octocosm-bench-render --save-pictures` writes (greyscale PFM, mass per
pixel), tone maps them alike (log curve, 4 decades below the reference's
99.5th percentile, as grey), and prints for each frame:
  - its PSNR on that grey scale (close to the bench's, which is taken on the
    colour map);
  - the share of the squared error in each band of the reference's
    brightness (the dim background to the bright filaments and halos);
  - the error's rms left after averaging it over 4x4 and 16x16 pixels: the
    part of it at scales above 4 and 16 pixels.

  python3 bench/error_map.py DIR/reference-mid.pfm DIR/picture-mid-clusters-t16-b0.pfm ...
"""
import sys

import numpy as np


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        if kind not in (b"Pf", b"PF"):
            sys.exit(f"{path}: not a PFM file")
        width, height = map(int, f.readline().split())
        scale = float(f.readline())
        values = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    channels = 1 if kind == b"Pf" else 3
    if values.size != width * height * channels:
        sys.exit(f"{path}: {values.size} values for {width}x{height}x{channels}")
    return values.reshape(height, width, channels)[::-1, :, 0].astype(np.float64)


def box_mean(image, k):
    h, w = image.shape[0] // k, image.shape[1] // k
    return image[: h * k, : w * k].reshape(h, k, w, k).mean(axis=(1, 3))


def ssim(a, b):
    """Mean SSIM of two images in [0, 1]: an 11-pixel Gaussian window of sigma
    1.5 over the pixels it fits in, as render/image_metrics.cc computes it."""
    taps = np.exp(-np.arange(-5, 6) ** 2 / (2 * 1.5**2))
    taps /= taps.sum()

    def filtered(image):
        rows = sum(t * image[:, i : image.shape[1] - 10 + i] for i, t in enumerate(taps))
        return sum(t * rows[i : image.shape[0] - 10 + i, :] for i, t in enumerate(taps))

    mx, my = filtered(a), filtered(b)
    vx, vy, cxy = filtered(a * a) - mx * mx, filtered(b * b) - my * my, filtered(a * b) - mx * my
    c1, c2 = 0.01**2, 0.03**2
    return float(np.mean((2 * mx * my + c1) * (2 * cxy + c2) / ((mx * mx + my * my + c1) * (vx + vy + c2))))


def grey_scale(reference, name):
    """The tone map of the comparisons: mass per pixel to a brightness in [0, 1],
    log scale, 4 decades below the reference's 99.5th percentile."""
    lit = reference[reference > 0]
    if lit.size == 0:
        sys.exit(f"{name}: an empty picture")
    exposure = np.percentile(lit, 99.5)
    floor = exposure * 1e-4

    def brightness(mass):
        with np.errstate(divide="ignore"):
            b = np.log(np.maximum(mass, 1e-300) / floor) / np.log(exposure / floor)
        return np.clip(np.where(mass > 0, b, 0), 0, 1)

    return brightness


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    reference = read_pfm(sys.argv[1])
    brightness = grey_scale(reference, sys.argv[1])
    truth = brightness(reference)
    bands = [(0.0, 0.2), (0.2, 0.4), (0.4, 0.6), (0.6, 0.8), (0.8, 1.01)]
    for path in sys.argv[2:]:
        picture = read_pfm(path)
        if picture.shape != reference.shape:
            sys.exit(f"{path}: {picture.shape} pixels, the reference {reference.shape}")
        error = brightness(picture) - truth
        squared = (error**2).sum()
        mse = np.mean(error**2)
        psnr = -10 * np.log10(mse) if mse > 0 else float("inf")
        print(f"{path}: {psnr:.2f} dB (grey), mass {picture.sum() / reference.sum():.5f} of the reference's")
        for lo, hi in bands:
            band = (truth >= lo) & (truth < hi)
            if band.any() and squared > 0:
                print(f"  reference brightness {lo:.1f}-{min(hi, 1):.1f}: {100 * band.mean():5.1f}% of the pixels, "
                      f"{100 * (error[band] ** 2).sum() / squared:5.1f}% of the squared error")
        rms = np.sqrt(mse)
        for k in (4, 16):
            above = np.sqrt(np.mean(box_mean(error, k) ** 2))
            print(f"  rms error {rms:.4f}; averaged over {k}x{k} pixels {above:.4f} "
                  f"({100 * (above / rms) ** 2 if rms > 0 else 0:.0f}% of the squared error at scales above {k} px)")


if __name__ == "__main__":
    main()
