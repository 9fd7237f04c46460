#!/usr/bin/env python3
"""Laser speckle on a stripe, from first principles: an independent model for the renderer's test.

What it computes: the scatter (px, RMS over image rows) of the intensity centroid across a laser
line, per row, caused by speckle alone, for a Gaussian sheet of geometric width σ = s px in the
image, a lens of working F-number N and a blur circle of d px. The renderer's coherent imager is
checked against these figures (crates/omni-simulator/tests/optics.rs,
`speckle_on_a_line_follows_an_independent_model_of_width_and_defocus`; docs/DECISIONS.md,
2026-12-06). This code shares nothing with the renderer.

Model (scalar Fourier optics in image space, fully developed speckle, units of pixels of
4.65 µm, λ = 650 nm):
* the ideal geometric image field U0(x, y) = sqrt(I(x)) · exp(i·φ), φ independent and uniform
  on a grid of scatterers 1/8 px apart (1/64 px across a sheet narrower than 0.2 px), I(x) a
  Gaussian of σ = s around x0, uniform along the line (periodic along y);
* the coherent pupil: a disc of cutoff NA/λ = 1/(2λN), with the defocus phase
  exp(−iπλΔz|f|²), Δz = N·d (the geometric blur circle's diameter is Δz/N);
* intensities |U|² integrated exactly over each pixel (a sinc in Fourier space); two or
  sixteen independent patterns added in intensity for C = 1/√2 and 1/4;
* per row, the centroid over |x − x0| ≤ 5σ_tot + d px (σ_tot² = s² + (0.42λN)² + d²/16), less
  the centroid of the speckle-free (ensemble-mean) image, which the model computes exactly.

Findings (F/4, C 0.71): a line scatters as √σ_tot once it is wider than the speckle grain
(0.129 / 0.185 / 0.261 px at s 0.8 / 1.7 / 3.4), unlike Dorsch's spot (C·λN/π, independent of
its size); a blur circle adds (k·C·d)² to the variance, k ≈ 0.05–0.09 with s and N; the
errors of neighbouring rows are nearly independent (correlation 0.14 at 1 px).

Usage: scripts/speckle_line_model.py --f-number 4 --sigma 1.7 --defocus 0 [--groups 8]
(numpy; each case takes 10–40 s). Prints one line per case and writes JSON with --json FILE.
"""
import argparse
import json
import time

import numpy as np

P_UM = 4.65
LAM_UM = 0.65
LAM = LAM_UM / P_UM  # wavelength (px)
HY = 1.0 / 8  # field and intensity grid spacing along the line (px)
HX = 1.0 / 8  # and across it
HXO_INV = 64.0  # scatterer columns per px across a thin sheet
MY = int(round(1 / HY))
MX = int(round(1 / HX))


def nice_len(n, step=16):
    return int(step * np.ceil(n / step))


def run_case(N, s, d, ly=256, n_groups=8, n_per_group=16, seed=0, extra_win=3.0):
    rng = np.random.default_rng(seed)
    fc = 0.5 / (LAM * N)                     # coherent cutoff NA/λ, cycles/px
    dz = N * d                               # image-space defocus (px)
    sig_diff = 0.42 * LAM * N
    sig_tot = np.sqrt(s**2 + sig_diff**2 + d**2 / 16.0)
    W = 5 * sig_tot + d
    W2 = W + extra_win
    lx = nice_len(2 * W2 + 2 * d + 16)
    ny, nx = ly * MY, lx * MX
    fy = np.fft.fftfreq(ny, HY)
    fx = np.fft.fftfreq(nx, HX)
    FY, FX = np.meshgrid(fy, fx, indexing="ij")
    R2 = FX**2 + FY**2
    pupil = (R2 <= fc**2) * np.exp(-1j * np.pi * LAM * dz * R2)
    pupil = pupil.astype(np.complex64)
    # sampling checks
    assert 2 * fc < 0.5 / HX and 2 * fc < 0.5 / HY, "intensity would alias"
    dphi_per_sample = np.pi * d / lx   # max defocus phase step per pupil sample (x)
    assert dphi_per_sample < 1.0, dphi_per_sample
    band_x = np.where(np.abs(fx) <= fc + 1e-12)[0]
    sincpix = (np.sinc(fy)[:, None] * np.sinc(fx)[None, :]).astype(np.complex64)

    # line-spread OTF of the discrete system for the mean image
    h = np.fft.ifft2(pupil.astype(np.complex128))
    lsf = (np.abs(h)**2).sum(axis=0)          # sum over y -> function of x on grid
    otf_x = np.fft.fft(lsf)                   # coefficients at fx
    # pixel centres (integer px) 0..lx-1 ; grid x_m = m*HX
    npix = np.arange(lx)

    thin = s < 0.2
    if thin:
        hxo = 1.0 / HXO_INV
        half = 6.5 * s * np.sqrt(2)
        offs = np.arange(-np.ceil(half / hxo), np.ceil(half / hxo) + 1) * hxo
    xg = np.arange(nx) * HX

    def fold_ifft(F):
        Ff = F.reshape(MY, ly, MX, lx).sum(axis=(0, 2))
        return np.fft.ifft2(Ff) / (MY * MX)

    res_err = {1: [], 2: [], 16: []}       # keyed by n patterns summed
    res_err_truth = {1: [], 2: [], 16: []}
    res_err_w2 = {1: [], 2: [], 16: []}
    for g in range(n_groups):
        x0 = lx / 2 + (g + rng.uniform(0, 1)) / n_groups   # stratified sub-pixel phase
        if thin:
            xj = x0 + offs
            envj = np.exp(-(xj - x0)**2 / (4 * s**2))      # amplitude
            E = np.exp(-2j * np.pi * np.outer(xj, fx[band_x])).astype(np.complex64)
            Gk = np.exp(-2j * np.pi * np.outer(fx, xj)) @ (envj**2)
        else:
            env = np.exp(-(xg - x0)**2 / (4 * s**2))
            cols = np.where(env > 1e-6)[0]
            envc = env[cols]
            Gk = np.exp(-2j * np.pi * np.outer(fx, xg[cols])) @ (envc**2)
        # mean (speckle-free incoherent) image, pixel integrated, per column
        spec = Gk * otf_x * np.sinc(fx)
        Ffold = spec.reshape(MX, lx).sum(axis=0)
        mean_prof = np.real(np.fft.ifft(Ffold)) / MX
        win = np.abs(npix - x0) <= W
        win2 = np.abs(npix - x0) <= W2
        cm = (npix[win] * mean_prof[win]).sum() / mean_prof[win].sum()
        cm2 = (npix[win2] * mean_prof[win2]).sum() / mean_prof[win2].sum()

        pix_imgs = []
        for pair in range(n_per_group // 2):
            Is = []
            for _ in range(2):
                if thin:
                    ph = rng.uniform(0, 2 * np.pi, size=(ny, len(xj)))
                    A = (envj[None, :] * np.exp(1j * ph)).astype(np.complex64)
                    Ay = np.fft.fft(A, axis=0)
                    Uh = np.zeros((ny, nx), np.complex64)
                    Uh[:, band_x] = Ay @ E
                else:
                    ph = rng.uniform(0, 2 * np.pi, size=(ny, len(cols)))
                    A = np.zeros((ny, nx), np.complex64)
                    A[:, cols] = (envc[None, :] * np.exp(1j * ph)).astype(np.complex64)
                    Uh = np.fft.fft2(A)
                U = np.fft.ifft2(Uh * pupil)
                Is.append((U.real**2 + U.imag**2).astype(np.float32))
            Z = (Is[0] + 1j * Is[1]).astype(np.complex64)
            F = np.fft.fft2(Z) * sincpix
            pz = fold_ifft(F)
            pix_imgs.append(pz.real.astype(np.float64))
            pix_imgs.append(pz.imag.astype(np.float64))
        pix_imgs = np.array(pix_imgs)          # (16, ly, lx)

        def centroids(img, w):
            prof = img[:, w]
            return (prof * npix[w]).sum(axis=1) / prof.sum(axis=1)

        for npat in (1, 2, 16):
            for k in range(0, n_per_group, npat):
                img = pix_imgs[k:k + npat].sum(axis=0)
                c = centroids(img, win)
                c2 = centroids(img, win2)
                res_err[npat].append(c - cm)
                res_err_truth[npat].append(c - x0)
                res_err_w2[npat].append(c2 - cm2)

    out = dict(N=N, s=s, d=d, W=W, lx=lx, ly=ly,
               sig_tot=sig_tot,
               dorsch_px=LAM * N / np.pi)
    for npat in (1, 2, 16):
        e = np.array(res_err[npat])            # (nreal, ly)
        et = np.array(res_err_truth[npat])
        e2 = np.array(res_err_w2[npat])
        ms = (e**2).mean()
        rms = np.sqrt(ms)
        gms = (e**2).reshape(n_groups, -1).mean(axis=1)   # per sub-pixel-phase group
        se_grp = gms.std(ddof=1) / np.sqrt(n_groups) / (2 * rms)
        blocks = (e**2).reshape(-1, 32).mean(axis=1)
        se = blocks.std(ddof=1) / np.sqrt(len(blocks)) / (2 * rms)
        acf = {}
        for lag in (1, 2, 3, 4, 6, 8):
            acf[lag] = float((e * np.roll(e, -lag, axis=1)).mean() / ms)
        C = 1 / np.sqrt(npat)
        out[f"C{npat}"] = dict(C=C, rms=float(rms), se=float(se), se_grp=float(se_grp), n_rows=int(e.size),
                              bias_truth=float(et.mean()),
                              rms_truth=float(np.sqrt((et**2).mean())),
                              rms_w2=float(np.sqrt((e2**2).mean())),
                              acf=acf)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--f-number", default="4", help="working F-numbers, comma-separated")
    ap.add_argument("--sigma", default="0.083,0.8,1.7", help="sheet σ in the image (px), comma-separated")
    ap.add_argument("--defocus", default="0,6", help="blur circle diameters (px), comma-separated")
    ap.add_argument("--groups", type=int, default=8, help="sub-pixel positions (16 patterns each)")
    ap.add_argument("--json", help="write every case's figures here")
    args = ap.parse_args()
    floats = lambda text: [float(v) for v in text.split(",")]  # noqa: E731
    results = []
    for n in floats(args.f_number):
        for s in floats(args.sigma):
            for d in floats(args.defocus):
                start = time.time()
                seed = hash((n, s, d, 0.5)) % (2**32)
                r = run_case(n, s, d, n_groups=args.groups, seed=seed)
                results.append(r)
                print(
                    f"F/{n:g} sheet σ {s:g} px, circle {d:g} px: scatter C 1 {r['C1']['rms']:.4f}, "
                    f"C 0.71 {r['C2']['rms']:.4f} ± {r['C2']['se']:.4f}, C 0.25 {r['C16']['rms']:.4f} px "
                    f"({time.time() - start:.0f} s)",
                    flush=True,
                )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
