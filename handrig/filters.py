"""Smoothing for glove channels: the One Euro filter, vectorised over channels.

Casiez, Roussel and Vogel, "1 Euro Filter: A Simple Speed-based Low-pass Filter
for Noisy Input in Interactive Systems" (CHI 2012). Per channel, with sample
period ``Te``::

    alpha(fc) = 1 / (1 + tau / Te),   tau = 1 / (2 pi fc)
    dx        = (x - x_hat_prev) / Te
    dx_hat    = dx_hat_prev + alpha(d_cutoff) * (dx - dx_hat_prev)
    fc        = min_cutoff + beta * |dx_hat|
    x_hat     = x_hat_prev + alpha(fc) * (x - x_hat_prev)

Slow motion gets the low ``min_cutoff`` (little jitter); fast motion raises the
cutoff in proportion to speed (little lag). The paper's defaults: min_cutoff 1
Hz, beta 0, d_cutoff 1 Hz. Tuning (the paper's procedure): with beta = 0, lower
min_cutoff until jitter at rest is acceptable; then raise beta until fast
motion no longer lags.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
TWO_PI = 2.0 * math.pi
SCALAR_MAX_CHANNELS = 32
"""Up to this many channels a plain-float loop is faster than numpy's per-call overhead
(5 channels: about 2 us against 14 us on the reference machine)."""


class OneEuroFilter:
    """One Euro filter over ``n`` channels; a step allocates no arrays.

    ``min_cutoff_hz``, ``beta`` (cutoff Hz per unit/s of speed, e.g. per deg/s)
    and ``d_cutoff_hz`` may be scalars or per-channel arrays of shape (n,).
    ``filter(x, t_s, out)`` takes the newest values (n,) and their time in
    seconds; the first call (and the first after :meth:`reset`) passes ``x``
    through. A call whose time does not advance returns the previous output.
    """

    def __init__(
        self,
        n: int,
        min_cutoff_hz: ArrayLike = 1.0,
        beta: ArrayLike = 0.0,
        d_cutoff_hz: ArrayLike = 1.0,
    ) -> None:
        if n < 1:
            raise ValueError(f"n must be at least 1, got {n}")
        self.n = n
        self.min_cutoff_hz = self._param(min_cutoff_hz, "min_cutoff_hz", positive=True)
        self.beta = self._param(beta, "beta", positive=False)
        self.d_cutoff_hz = self._param(d_cutoff_hz, "d_cutoff_hz", positive=True)
        self._two_pi_d = TWO_PI * self.d_cutoff_hz
        self._x_hat = np.zeros(n)
        self._dx_hat = np.zeros(n)
        self._dx = np.zeros(n)
        self._a = np.zeros(n)
        self._fc = np.zeros(n)
        self._t_s = -math.inf
        self._primed = False
        self._scalar = n <= SCALAR_MAX_CHANNELS
        self._xl = [0.0] * n
        self._dxl = [0.0] * n
        self._mc = self.min_cutoff_hz.tolist()
        self._beta = self.beta.tolist()
        self._dc2pi = self._two_pi_d.tolist()

    def _param(self, value: ArrayLike, name: str, *, positive: bool) -> FloatArray:
        arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (self.n,)).copy()
        if not np.all(np.isfinite(arr)) or np.any(arr <= 0 if positive else arr < 0):
            rule = "positive" if positive else "zero or positive"
            raise ValueError(f"{name} must be finite and {rule}, got {value!r}")
        return arr

    def reset(self) -> None:
        """Forget the history: the next call passes its input through."""
        self._primed = False
        self._dx_hat.fill(0.0)
        self._dxl = [0.0] * self.n

    @property
    def value(self) -> FloatArray:
        """The last output (n,); read-only view."""
        v = self._x_hat.view()
        v.flags.writeable = False
        return v

    def __call__(self, x: FloatArray, t_s: float, out: FloatArray | None = None) -> FloatArray:
        return self.filter(x, t_s, out)

    def filter(self, x: FloatArray, t_s: float, out: FloatArray | None = None) -> FloatArray:
        """Filter ``x`` (n,) sampled at ``t_s``; writes into ``out`` if given (may be ``x``)."""
        xh = self._x_hat
        if not self._primed:
            xh[:] = x
            self._xl = xh.tolist()
            self._t_s = t_s
            self._primed = True
        else:
            te = t_s - self._t_s
            if te > 0.0:
                self._t_s = t_s
                if self._scalar:
                    self._step_scalar(x, te)
                else:
                    self._step_vector(x, te)
        if out is None:
            return xh.copy()
        out[:] = xh
        return out

    def _step_scalar(self, x: FloatArray, te: float) -> None:
        xl, dxl, mc, beta, dc2pi = self._xl, self._dxl, self._mc, self._beta, self._dc2pi
        two_pi_te = TWO_PI * te
        for i, xi in enumerate(x.tolist()):
            prev = xl[i]
            a_d = 1.0 / (1.0 + 1.0 / (dc2pi[i] * te))
            d = dxl[i] + a_d * ((xi - prev) / te - dxl[i])
            dxl[i] = d
            fc = mc[i] + beta[i] * abs(d)
            xl[i] = prev + (xi - prev) / (1.0 + 1.0 / (two_pi_te * fc))
        self._x_hat[:] = xl

    def _step_vector(self, x: FloatArray, te: float) -> None:
        xh = self._x_hat
        dx, a, fc = self._dx, self._a, self._fc
        np.subtract(x, xh, out=dx)
        dx *= 1.0 / te
        # alpha = 1 / (1 + 1 / (2 pi fc Te))
        np.multiply(self._two_pi_d, te, out=a)
        np.reciprocal(a, out=a)
        a += 1.0
        np.reciprocal(a, out=a)
        dx -= self._dx_hat
        dx *= a
        self._dx_hat += dx
        np.abs(self._dx_hat, out=fc)
        fc *= self.beta
        fc += self.min_cutoff_hz
        fc *= TWO_PI * te
        np.reciprocal(fc, out=fc)
        fc += 1.0
        np.reciprocal(fc, out=fc)
        np.subtract(x, xh, out=dx)
        dx *= fc
        xh += dx
