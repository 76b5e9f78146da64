"""Augmented MCL: short- and long-term averages of the measurement likelihood decide how many random particles to inject.

After Thrun, Burgard & Fox, Probabilistic Robotics (2005), Table 8.3: w_slow and w_fast are exponential
averages (rates alpha_slow < alpha_fast) of the average particle likelihood; when the recent average
falls below the long-term one (the readings no longer fit the particles: a kidnapped robot, a wrong
global hypothesis), each particle is replaced at resampling with probability max(0, 1 - w_fast / w_slow)
by a uniformly drawn pose. Here the average likelihood is taken per reading (geometric mean over the
step's readings, so steps with many readings do not look better than steps with few), and both
averages start at zero with bias correction (each is a proper weighted mean of the steps seen so far).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class LikelihoodAverages:
    """Running w_slow / w_fast of the per-reading average likelihood (values in (0, 1])."""

    alpha_slow: float = 0.001
    alpha_fast: float = 0.1
    w_slow: float = 0.0
    w_fast: float = 0.0
    n_updates: int = 0

    def update(self, log_mean_likelihood_per_reading: float) -> None:
        """Fold in one step's log of the average particle likelihood per reading (non-finite values are skipped)."""
        if not math.isfinite(log_mean_likelihood_per_reading):
            return
        w = math.exp(min(log_mean_likelihood_per_reading, 0.0))  # the likelihood's normalizing constant is dropped: <= 1
        self.w_slow += self.alpha_slow * (w - self.w_slow)
        self.w_fast += self.alpha_fast * (w - self.w_fast)
        self.n_updates += 1

    def _corrected(self, value: float, alpha: float) -> float:
        # 1 - (1 - alpha)^n, exact for tiny rates: below ~5.5e-17 1 - alpha rounds to 1 and the divisor was 0
        # (ZeroDivisionError at the first resampling of --augmented --alpha-slow 1e-17)
        if alpha >= 1.0:  # (the latest value alone: nothing to correct; log1p(-1) is undefined)
            return value
        return value / -math.expm1(self.n_updates * math.log1p(-alpha))

    def injection_probability(self) -> float:
        """max(0, 1 - w_fast / w_slow) with bias-corrected averages; 0 before the first update."""
        if self.n_updates == 0:
            return 0.0
        slow = self._corrected(self.w_slow, self.alpha_slow)
        fast = self._corrected(self.w_fast, self.alpha_fast)
        if not slow > 0.0:
            return 0.0
        return max(0.0, 1.0 - fast / slow)


__all__ = ["LikelihoodAverages"]
