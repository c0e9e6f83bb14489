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
