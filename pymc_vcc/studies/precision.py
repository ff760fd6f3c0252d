"""Numbers in printed tables shown to the precision they have.

A posterior mean is as precise as its sd allows: both are printed to the decimal place of the
sd's second significant figure (an sd of 0.013 kg: ``1.997 ± 0.013``; of 0.00011 kg:
``1.50018 ± 0.00011``), so that a small sd is never rounded to ``0.000``.
"""

from __future__ import annotations

import math

SIGNIFICANT = 2
"""Significant figures an uncertainty is printed with."""


def decimals(uncertainty: float, significant: int = SIGNIFICANT, fallback: int = 3) -> int:
    """Decimal places that show ``uncertainty`` to ``significant`` figures.

    Parameters
    ----------
    uncertainty
        An sd, an error or an interval width, in any unit.
    significant
        Significant figures of ``uncertainty`` to show.
    fallback
        Decimal places for an uncertainty of 0 or one that is not finite.
    """
    if not math.isfinite(uncertainty) or uncertainty == 0.0:
        return fallback
    return max(0, significant - 1 - math.floor(math.log10(abs(uncertainty))))


def fixed(value: float, places: int, width: int = 0) -> str:
    """``value`` with ``places`` decimals, right-aligned in ``width`` characters."""
    return f"{value:{width}.{places}f}"


def significant(value: float, figures: int = SIGNIFICANT, width: int = 0) -> str:
    """``value`` to ``figures`` significant figures in fixed notation (``0.00007``, not
    ``7e-05``), right-aligned in ``width`` characters."""
    return fixed(value, decimals(value, figures), width)
