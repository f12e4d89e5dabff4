"""Error of a shadow mask against the exact answer: false shadow and false light."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class MaskError:
    """How a mask differs from the truth. ``false_shadow``: lit points called shadowed; ``false_light``: the reverse."""

    receivers: int
    false_shadow: int
    false_light: int

    @property
    def wrong(self) -> int:
        """Misclassified receivers: false shadow plus false light."""
        return self.false_shadow + self.false_light

    @property
    def fraction(self) -> float:
        """Misclassified receivers as a fraction of all (0 for no receivers)."""
        return self.wrong / self.receivers if self.receivers else 0.0

    def as_dict(self) -> dict:
        """The counts with ``wrong`` and ``percent``, for JSON rows."""
        return {**asdict(self), "wrong": self.wrong, "percent": 100.0 * self.fraction}

    def __str__(self) -> str:
        return (
            f"{self.wrong} of {self.receivers} wrong ({100 * self.fraction:.4f} %): "
            f"{self.false_shadow} false shadow, {self.false_light} false light"
        )


def mask_error(mask, truth) -> MaskError:
    """Compare bool masks of equal shape; ``truth`` is the exact method's mask."""
    mask, truth = np.asarray(mask), np.asarray(truth)
    if mask.shape != truth.shape:
        raise ValueError(f"mask: shape {mask.shape} differs from the truth's {truth.shape}")
    if mask.dtype != bool or truth.dtype != bool:
        raise TypeError(f"mask: expected bool masks, got {mask.dtype} and {truth.dtype}")
    return MaskError(
        receivers=int(mask.size),
        false_shadow=int(np.count_nonzero(mask & ~truth)),
        false_light=int(np.count_nonzero(~mask & truth)),
    )
