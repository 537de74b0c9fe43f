"""Wavelength bins of the radiosity solution.

The solution is one spectrum per patch, sampled at ``K`` bin centres that split
[360, 830] nm into equal bins. Reflectances and emission are evaluated *at* the centres
(point sampling), and a spectrum between centres is their linear interpolation (held
constant beyond the first and last centre). The same reconstruction serves rendering (at
the wavelengths a camera sample carries) and display (XYZ weights below), so an exported
colour and a rendered pixel of one patch agree.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from ... import spectrum as spec


class WavelengthBins:
    def __init__(self, count: int):
        self.count = int(count)
        self.width = (spec.LAMBDA_MAX - spec.LAMBDA_MIN) / self.count
        self.centers = spec.LAMBDA_MIN + (np.arange(self.count) + 0.5) * self.width

    def groups(self) -> list[list[float]]:
        """The centres in groups of four (a sampled spectrum's lanes), the last group
        padded with its last centre."""
        c = self.centers.tolist()
        c += [c[-1]] * (-len(c) % spec.N_WAVELENGTHS)
        return [c[i:i + spec.N_WAVELENGTHS] for i in range(0, len(c), spec.N_WAVELENGTHS)]

    def hat_weights(self, lam: np.ndarray) -> np.ndarray:
        """(len(lam), K) weights of each bin's value in the reconstruction at ``lam``."""
        t = np.clip((np.asarray(lam, np.float64) - self.centers[0]) / self.width, 0.0, self.count - 1.0)
        i0 = np.minimum(np.floor(t).astype(np.int64), self.count - 2)
        w1 = t - i0
        W = np.zeros((len(t), self.count))
        W[np.arange(len(t)), i0] = 1.0 - w1
        W[np.arange(len(t)), i0 + 1] += w1
        return W

    def xyz_weights(self) -> np.ndarray:
        """(3, K) matrix: XYZ = M @ spectrum, with pbr's CIE normalisation
        (XYZ = integral of cmf(l) L(l) dl / CIE_Y_INTEGRAL), integrated at 1 nm over the
        reconstructed spectrum with the CIE tables interpolated as the film does."""
        lam = np.arange(spec.LAMBDA_MIN, spec.LAMBDA_MAX + 0.5, 1.0)
        xyz, _ = spec.cie_tables_np()
        grid = spec.LAMBDA_MIN + 5.0 * np.arange(len(xyz))
        cmf = np.stack([np.interp(lam, grid, xyz[:, c]) for c in range(3)])
        dl = np.full(len(lam), 1.0)
        dl[[0, -1]] = 0.5                                  # trapezoid rule
        return (cmf * dl) @ self.hat_weights(lam) / spec.CIE_Y_INTEGRAL

    def to_srgb(self, spectra: np.ndarray) -> np.ndarray:
        """Linear sRGB of (..., K) binned spectra."""
        return spec.xyz_to_srgb(np.asarray(spectra, np.float64) @ self.xyz_weights().T)

    def lookup(self, table: mi.Float, row: mi.UInt32, lam: mi.Spectrum, active) -> mi.Spectrum:
        """The binned spectrum ``table[row * K : (row + 1) * K]`` reconstructed at the
        wavelengths ``lam`` (one lane each)."""
        K = self.count
        out = []
        for i in range(spec.N_WAVELENGTHS):
            t = dr.clip((lam[i] - float(self.centers[0])) * (1.0 / self.width), 0.0, K - 1.0)
            i0 = dr.minimum(mi.UInt32(t), K - 2)
            w1 = t - mi.Float(i0)
            base = row * K + i0
            v0 = dr.gather(mi.Float, table, base, active)
            v1 = dr.gather(mi.Float, table, base + 1, active)
            out.append(dr.fma(w1, v1 - v0, v0))
        return mi.Spectrum(out)
