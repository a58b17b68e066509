#!/usr/bin/env python3
"""Write OpenCV-made calibration fixtures and reference rectification results.

Usage: opencv_fixtures.py OUTDIR

For each stereo case (horizontal baseline with 5 distortion coefficients,
vertical baseline, 8-coefficient rational model, 4 coefficients) it writes,
under OUTDIR/<case>/:

  single/calibration.yml        M1 D1 M2 D2 R T image_width image_height (cv2.FileStorage)
  pair/intrinsics.yml           M1 D1 M2 D2  (OpenCV stereo_calib sample layout)
  pair/extrinsics.yml           R T R1 R2 P1 P2 Q
  alias_lr/calibration.yml      cameraMatrixL/R distCoeffsL/R R T + size, D as 1xN
  alias_12/calibration.yml      cameraMatrix1/2 distCoeffs1/2 R T + size, D as Nx1
  npz/cal.npz                   VIAME camtrawl keys (numpy.savez, one array Fortran-ordered)
  reference.json                image size, the model, and cv2.stereoRectify(...,
                                flags=CALIB_ZERO_DISPARITY, alpha=0) -> R1 R2 P1 P2 Q,
                                raw<->rectified point pairs (cv2.undistortPoints with
                                R=Ri, P=Pi and tight criteria) for both cameras
  left.png right.png            a textured raw test image (the same for both sides)
  left_rect.png right_rect.png  cv2.remap(INTER_LINEAR, BORDER_CONSTANT) of it through
                                cv2.initUndistortRectifyMap(..., CV_32FC1)
  left_map.f32 right_map.f32    those float maps, little-endian f32, x plane then y plane
  left_rep.png right_rep.png    the same remap with BORDER_REPLICATE
  left_ref.png right_ref.png    the same remap with BORDER_REFLECT_101 (FishTrack's fill)

and the same set for alpha = 1 (keep every source pixel) and alpha = -1
(OpenCV's default scaling) with the suffix _a1 / _am1 on every name
(reference_a1.json, left_rect_a1.png, left_map_a1.f32, left_ref_a1.png, ...);
the calibration files are the same for every alpha.

Everything is deterministic (fixed seeds).
"""
import json
import os
import sys

import cv2
import numpy as np

W, H = 320, 240


def rodrigues(v):
    r, _ = cv2.Rodrigues(np.array(v, dtype=np.float64).reshape(3, 1))
    return r


CASES = {
    # Cam-trawl-like: cameras side by side, slight toe-in, barrel distortion.
    "horizontal5": dict(
        m1=[[412.5, 0, 158.3], [0, 410.9, 121.7], [0, 0, 1]],
        d1=[-0.21, 0.09, 0.0012, -0.0008, -0.02],
        m2=[[418.2, 0, 163.9], [0, 416.0, 118.4], [0, 0, 1]],
        d2=[-0.19, 0.07, -0.0006, 0.0011, -0.015],
        rvec=[0.012, -0.061, 0.0045],
        t=[-120.4, 1.3, 2.9],
    ),
    # cameras one above the other
    "vertical5": dict(
        m1=[[395.0, 0, 161.2], [0, 396.5, 117.3], [0, 0, 1]],
        d1=[-0.15, 0.05, 0.0005, 0.0003, 0.0],
        m2=[[401.7, 0, 157.6], [0, 402.2, 123.8], [0, 0, 1]],
        d2=[-0.16, 0.06, -0.0004, 0.0002, -0.01],
        rvec=[0.045, 0.008, -0.011],
        t=[2.1, -98.7, -3.4],
    ),
    # rational model, 8 coefficients k1 k2 p1 p2 k3 k4 k5 k6; pincushion-ish left camera
    "rational8": dict(
        m1=[[380.0, 0, 162.0], [0, 381.5, 119.0], [0, 0, 1]],
        d1=[0.12, -0.05, 0.001, -0.002, 0.01, 0.08, -0.02, 0.004],
        m2=[[385.0, 0, 157.5], [0, 384.0, 121.5], [0, 0, 1]],
        d2=[-0.3, 0.12, -0.0015, 0.0007, -0.02, -0.1, 0.03, 0.002],
        rvec=[-0.02, 0.035, 0.01],
        t=[-80.0, -4.0, 1.5],
    ),
    # only k1 k2 p1 p2; right camera to the left of the left one (T.x > 0)
    "k4": dict(
        m1=[[450.0, 0, 159.5], [0, 450.0, 119.5], [0, 0, 1]],
        d1=[-0.05, 0.01, 0.0, 0.0],
        m2=[[447.0, 0, 160.5], [0, 449.0, 120.0], [0, 0, 1]],
        d2=[-0.06, 0.015, 0.0002, -0.0001],
        rvec=[0.003, 0.02, -0.002],
        t=[60.0, 0.5, -0.8],
    ),
}


def test_image(seed):
    rng = np.random.default_rng(seed)
    noise = rng.random((H, W)).astype(np.float32)
    img = cv2.GaussianBlur(noise, (0, 0), 2.0)
    img -= img.min()
    img *= 255.0 / img.max()
    # a few sharp-edged shapes too, so geometry errors show
    img = img.astype(np.uint8)
    for i in range(12):
        c = (int(rng.integers(0, W)), int(rng.integers(0, H)))
        cv2.circle(img, c, int(rng.integers(5, 25)), int(rng.integers(0, 256)), -1, cv2.LINE_AA)
    return cv2.GaussianBlur(img, (0, 0), 0.8)


def write_fs(path, entries):
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    for k, v in entries:
        fs.write(k, v)
    fs.release()


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-12)
    for idx, (name, c) in enumerate(CASES.items()):
        d = os.path.join(out, name)
        for sub in ("single", "pair", "alias_lr", "alias_12", "npz"):
            os.makedirs(os.path.join(d, sub), exist_ok=True)
        m1 = np.array(c["m1"], dtype=np.float64)
        m2 = np.array(c["m2"], dtype=np.float64)
        d1 = np.array(c["d1"], dtype=np.float64).reshape(1, -1)
        d2 = np.array(c["d2"], dtype=np.float64).reshape(1, -1)
        r = rodrigues(c["rvec"])
        t = np.array(c["t"], dtype=np.float64).reshape(3, 1)
        # the stereo_calib sample's extrinsics.yml carries alpha = 0 results
        r1, r2, p1, p2, q, _, _ = cv2.stereoRectify(
            m1, d1, m2, d2, (W, H), r, t, flags=cv2.CALIB_ZERO_DISPARITY, alpha=0)

        write_fs(os.path.join(d, "single", "calibration.yml"),
                 [("image_width", W), ("image_height", H), ("M1", m1), ("D1", d1),
                  ("M2", m2), ("D2", d2), ("R", r), ("T", t)])
        write_fs(os.path.join(d, "pair", "intrinsics.yml"),
                 [("M1", m1), ("D1", d1), ("M2", m2), ("D2", d2)])
        write_fs(os.path.join(d, "pair", "extrinsics.yml"),
                 [("R", r), ("T", t), ("R1", r1), ("R2", r2), ("P1", p1), ("P2", p2), ("Q", q)])
        write_fs(os.path.join(d, "alias_lr", "calibration.yml"),
                 [("image_width", W), ("image_height", H),
                  ("cameraMatrixL", m1), ("distCoeffsL", d1),
                  ("cameraMatrixR", m2), ("distCoeffsR", d2), ("R", r), ("T", t)])
        write_fs(os.path.join(d, "alias_12", "calibration.yml"),
                 [("cameraMatrix1", m1), ("distCoeffs1", d1.reshape(-1, 1)),
                  ("cameraMatrix2", m2), ("distCoeffs2", d2.reshape(-1, 1)),
                  ("R", r), ("T", t), ("image_width", W), ("image_height", H)])
        np.savez(os.path.join(d, "npz", "cal.npz"),
                 cameraMatrixL=np.asfortranarray(m1), cameraMatrixR=m2,
                 distCoeffsL=d1, distCoeffsR=d2.reshape(-1), R=r, T=t.reshape(-1))

        img = test_image(1000 + idx)
        cv2.imwrite(os.path.join(d, "left.png"), img)
        cv2.imwrite(os.path.join(d, "right.png"), img)
        for alpha, tag in ((0, ""), (1, "_a1"), (-1, "_am1")):
            write_alpha(d, idx, img, m1, d1, m2, d2, r, t, crit, alpha, tag)
    print("wrote", ", ".join(CASES), "to", out)


def write_alpha(d, idx, img, m1, d1, m2, d2, r, t, crit, alpha, tag):
    """The references of one alpha, every file name suffixed with `tag`."""
    r1, r2, p1, p2, q, roi1, roi2 = cv2.stereoRectify(
        m1, d1, m2, d2, (W, H), r, t, flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha)
    ref = dict(alpha=alpha, width=W, height=H, M1=m1.tolist(), D1=d1.ravel().tolist(),
               M2=m2.tolist(), D2=d2.ravel().tolist(), R=r.tolist(),
               T=t.ravel().tolist(), R1=r1.tolist(), R2=r2.tolist(),
               P1=p1.tolist(), P2=p2.tolist(), Q=q.tolist(),
               roi1=list(roi1), roi2=list(roi2), opencv=cv2.__version__)
    rng = np.random.default_rng(77 + idx)
    raw = np.concatenate([
        rng.uniform([0, 0], [W - 1, H - 1], size=(200, 2)),
        np.array([[x, y] for x in (0, W / 2, W - 1) for y in (0, H / 2, H - 1)]),
    ]).astype(np.float64)
    for side, m, dd, ri, pi in (("left", m1, d1, r1, p1), ("right", m2, d2, r2, p2)):
        mx, my = cv2.initUndistortRectifyMap(m, dd, ri, pi, (W, H), cv2.CV_32FC1)
        rect = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0)
        cv2.imwrite(os.path.join(d, side + "_rect" + tag + ".png"), rect)
        rep = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        cv2.imwrite(os.path.join(d, side + "_rep" + tag + ".png"), rep)
        refl = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
        cv2.imwrite(os.path.join(d, side + "_ref" + tag + ".png"), refl)
        with open(os.path.join(d, side + "_map" + tag + ".f32"), "wb") as f:
            f.write(mx.astype("<f4").tobytes())
            f.write(my.astype("<f4").tobytes())
        und = cv2.undistortPoints(raw.reshape(-1, 1, 2), m, dd, R=ri, P=pi, criteria=crit)
        ref[side + "_raw"] = raw.tolist()
        ref[side + "_rect"] = und.reshape(-1, 2).tolist()
    with open(os.path.join(d, "reference" + tag + ".json"), "w") as f:
        json.dump(ref, f, indent=1)


if __name__ == "__main__":
    main()
