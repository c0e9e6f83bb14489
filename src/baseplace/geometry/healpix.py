"""HEALPix equal-area pixelization of the sphere, RING scheme, any ``nside``.

Written by hand (after Gorski et al. 2005, "HEALPix: a framework for high-resolution
discretization...", and the reference C implementation) because the reachability kernels need
``ang2pix`` inlined in compiled loops; healpy is the test oracle. Angles: ``z = cos(theta)``
with theta the colatitude, ``phi`` in [0, 2 pi).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from baseplace.geometry.poses import FloatArray

TWO_PI = 2.0 * math.pi


@nb.njit(cache=True, inline="always")
def ang2pix_ring(nside: int, z: float, phi: float) -> int:
    """Pixel index (RING scheme) of the direction with ``cos(theta) = z`` and azimuth ``phi``."""
    za = abs(z)
    tt = phi % TWO_PI
    tt = tt * (2.0 / math.pi)  # in [0, 4)
    if za <= 2.0 / 3.0:
        temp1 = nside * (0.5 + tt)
        temp2 = nside * z * 0.75
        jp = int(temp1 - temp2)
        jm = int(temp1 + temp2)
        ir = nside + 1 + jp - jm  # ring index counted from z = 2/3, in 1 .. 2 nside + 1
        kshift = 1 - (ir & 1)
        ip = (jp + jm - nside + kshift + 1) // 2
        ip = ip % (4 * nside)
        return 2 * nside * (nside - 1) + (ir - 1) * 4 * nside + ip
    tp = tt - int(tt)
    tmp = nside * math.sqrt(3.0 * (1.0 - za))
    jp = int(tp * tmp)
    jm = int((1.0 - tp) * tmp)
    ir = jp + jm + 1  # ring index counted from the nearest pole
    ip = int(tt * ir)
    ip = ip % (4 * ir)
    if z > 0:
        return 2 * ir * (ir - 1) + ip
    return 12 * nside * nside - 2 * ir * (ir + 1) + ip


def pix2ang_ring(nside: int) -> tuple[FloatArray, FloatArray]:
    """Centres of all ``12 nside^2`` pixels as ``(z, phi)`` arrays, RING order."""
    npix = 12 * nside * nside
    ncap = 2 * nside * (nside - 1)
    z = np.empty(npix)
    phi = np.empty(npix)
    for p in range(npix):
        if p < ncap:
            iring = (1 + math.isqrt(1 + 2 * p)) >> 1
            iphi = p + 1 - 2 * iring * (iring - 1)
            z[p] = 1.0 - iring * iring / (3.0 * nside * nside)
            phi[p] = (iphi - 0.5) * math.pi / (2.0 * iring)
        elif p < npix - ncap:
            ip = p - ncap
            iring = ip // (4 * nside) + nside
            iphi = ip % (4 * nside) + 1
            fodd = 1.0 if ((iring + nside) & 1) else 0.5
            z[p] = (2 * nside - iring) * 2.0 / (3.0 * nside)
            phi[p] = (iphi - fodd) * math.pi / (2.0 * nside)
        else:
            ip = npix - p
            iring = (1 + math.isqrt(2 * ip - 1)) >> 1
            iphi = 4 * iring + 1 - (ip - 2 * iring * (iring - 1))
            z[p] = -1.0 + iring * iring / (3.0 * nside * nside)
            phi[p] = (iphi - 0.5) * math.pi / (2.0 * iring)
    return z, phi


@nb.njit(cache=True, inline="always")
def _ring_info(nside: int, ring: int) -> tuple[int, int, float, bool]:
    """(first pixel, pixels in the ring, colatitude theta of its centres, whether it is shifted)."""
    npix = 12 * nside * nside
    north = 4 * nside - ring if ring > 2 * nside else ring
    if north < nside:
        tmp = north * north * (4.0 / npix)
        theta = math.atan2(math.sqrt(tmp * (2.0 - tmp)), 1.0 - tmp)
        ringpix = 4 * north
        shifted = True
        start = 2 * north * (north - 1)
    else:
        theta = math.acos((2 * nside - north) * (8.0 * nside / npix))
        ringpix = 4 * nside
        shifted = ((north - nside) & 1) == 0
        start = 2 * nside * (nside - 1) + (north - nside) * ringpix
    if north != ring:  # southern hemisphere
        theta = math.pi - theta
        start = npix - start - ringpix
    return start, ringpix, theta, shifted


@nb.njit(cache=True, inline="always")
def _ring_neighbours(nside: int, ring: int, phi: float, pix: np.ndarray, w: np.ndarray, at: int) -> float:
    """The two pixels of ``ring`` bracketing ``phi`` and their linear weights; returns the theta."""
    start, ringpix, theta, shifted = _ring_info(nside, ring)
    dphi = TWO_PI / ringpix
    tmp = phi / dphi - (0.5 if shifted else 0.0)
    i1 = math.floor(tmp)
    w1 = (phi - (i1 + (0.5 if shifted else 0.0)) * dphi) / dphi
    i2 = i1 + 1
    if i1 < 0:
        i1 += ringpix
    if i2 >= ringpix:
        i2 -= ringpix
    pix[at], pix[at + 1] = start + i1, start + i2
    w[at], w[at + 1] = 1.0 - w1, w1
    return theta


@nb.njit(cache=True, inline="always")
def interp_weights_ring(nside: int, z: float, phi: float, pix: np.ndarray, w: np.ndarray) -> None:
    """Bilinear interpolation on the sphere (HEALPix ``get_interpol``), RING scheme.

    Writes the 4 pixels around the direction ``(z, phi)`` into ``pix`` and their weights (sum 1)
    into ``w``.
    Linear in azimuth between the two nearest pixel centres of the rings above and below, then
    linear in colatitude between the rings; next to a pole, the polar cap's 4 pixels share the
    weight towards the pole.
    """
    z = min(1.0, max(-1.0, z))
    phi = phi % TWO_PI
    theta = math.acos(z)
    az = abs(z)
    if az <= 2.0 / 3.0:
        ir1 = int(nside * (2.0 - 1.5 * z))
    else:
        iring = int(nside * math.sqrt(3.0 * (1.0 - az)))
        ir1 = iring if z > 0 else 4 * nside - iring - 1
    ir2 = ir1 + 1
    npix = 12 * nside * nside
    theta1 = 0.0
    theta2 = math.pi
    if ir1 > 0:
        theta1 = _ring_neighbours(nside, ir1, phi, pix, w, 0)
    if ir2 < 4 * nside:
        theta2 = _ring_neighbours(nside, ir2, phi, pix, w, 2)
    if ir1 == 0:
        wtheta = theta / theta2
        fac = (1.0 - wtheta) * 0.25
        w[0], w[1] = fac, fac
        w[2], w[3] = w[2] * wtheta + fac, w[3] * wtheta + fac
        pix[0], pix[1] = (pix[2] + 2) & 3, (pix[3] + 2) & 3
    elif ir2 == 4 * nside:
        wtheta = (theta - theta1) / (math.pi - theta1)
        fac = wtheta * 0.25
        w[0], w[1] = w[0] * (1.0 - wtheta) + fac, w[1] * (1.0 - wtheta) + fac
        w[2], w[3] = fac, fac
        pix[2], pix[3] = ((pix[0] + 2) & 3) + npix - 4, ((pix[1] + 2) & 3) + npix - 4
    else:
        wtheta = (theta - theta1) / (theta2 - theta1)
        w[0], w[1] = w[0] * (1.0 - wtheta), w[1] * (1.0 - wtheta)
        w[2], w[3] = w[2] * wtheta, w[3] * wtheta
