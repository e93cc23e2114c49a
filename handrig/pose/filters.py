"""Smoothing for glove channels: the One Euro filter over every channel at once.

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

from handrig.pose import kernels

FloatArray = NDArray[np.float64]
TWO_PI = 2.0 * math.pi


class OneEuroFilter:
    """One Euro filter over ``n`` channels; a step allocates no arrays (one compiled
    loop, :func:`handrig.pose.kernels.one_euro_step`).

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
        self._t_s = -math.inf
        self._primed = False

    def _param(self, value: ArrayLike, name: str, *, positive: bool) -> FloatArray:
        arr = np.broadcast_to(np.asarray(value, dtype=np.float64), (self.n,)).copy()
        if not np.all(np.isfinite(arr)) or np.any(arr <= 0 if positive else arr < 0):
            rule = "positive" if positive else "zero or positive"
            raise ValueError(f"{name} must be finite and {rule}, got {value!r}")
        return arr

    def kernel_state(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """The arrays a compiled step that fuses this filter reads and updates in place:
        (x_hat, dx_hat, min_cutoff_hz, beta, 2 pi d_cutoff_hz), each (n,). They stay the
        same objects for the filter's life; call :meth:`advance` for each sample."""
        return self._x_hat, self._dx_hat, self.min_cutoff_hz, self.beta, self._two_pi_d

    def reset(self) -> None:
        """Forget the history: the next call passes its input through."""
        self._primed = False
        self._dx_hat.fill(0.0)

    @property
    def value(self) -> FloatArray:
        """The last output (n,); read-only view."""
        v = self._x_hat.view()
        v.flags.writeable = False
        return v

    def __call__(self, x: FloatArray, t_s: float, out: FloatArray | None = None) -> FloatArray:
        return self.filter(x, t_s, out)

    def advance(self, t_s: float) -> tuple[bool, float]:
        """Move the filter's clock to ``t_s`` for a sample taken then: (prime, te), where
        ``prime`` means the sample passes through (first call, or first after
        :meth:`reset`) and ``te`` is the step in seconds (no step unless > 0)."""
        if not self._primed:
            self._primed = True
            self._t_s = t_s
            return True, 0.0
        te = t_s - self._t_s
        if te > 0.0:
            self._t_s = t_s
        return False, te

    def filter(self, x: FloatArray, t_s: float, out: FloatArray | None = None) -> FloatArray:
        """Filter ``x`` (n,) sampled at ``t_s``; writes into ``out`` if given (may be ``x``)."""
        xh = self._x_hat
        prime, te = self.advance(t_s)
        if prime:
            xh[:] = x
        elif te > 0.0:
            kernels.one_euro_step(np.ascontiguousarray(x, dtype=np.float64), te, xh,
                                  self._dx_hat, self.min_cutoff_hz, self.beta, self._two_pi_d)
        if out is None:
            return xh.copy()
        out[:] = xh
        return out

