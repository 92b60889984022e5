"""The live loop's stamp screening (:class:`amsfe_sym.ros.live.LiveLoop`): which encoder
samples' header stamps are not used, by the log reader's rule on what a live node has
(docs/input-rules.md), and when a run of them holds the node.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from amsfe_sym.errors import EstimatorError, describe

__all__ = ["StampScreen"]


@dataclass
class StampScreen:
    """The screen of one live loop's encoder stamps.

    Attributes:
        T: The tick [s].
        T_ns: The tick [ns].
        max_gap: ``max_gap_steps``: the longest run of bad stamps passed over.
        last_sent: The last used sample's source timestamp [ns] (None: unknown).
        bad_run: Encoder samples with a bad stamp in a row.
    """

    T: float
    T_ns: int
    max_gap: int
    last_sent: int | None = None
    bad_run: int = 0

    def check(
        self, stamp_ns: int, sent_ns: int | None, t0_ns: int, k: int, skip: Callable[[str], None]
    ) -> str | None:
        """Why an encoder sample's header stamp is not used (None: it is), by the log
        reader's rule (docs/input-rules.md) on what a live node has: a zero stamp; a stamp
        more than ``max_gap_steps`` + 1 ticks behind the last used one (a clock step back);
        a stamp that many ticks ahead of it while the send times (DDS source timestamps)
        advanced less than a quarter as much (a clock step ahead or a corrupt stamp: a
        stall delays both).  Skipped and counted (``skip(why)``; ``t0_ns``, ``k``: the
        first sample's stamp [ns] and the last used tick); more than ``max_gap_steps`` in a
        row hold the node with the reason (a 1 h stamp was held as "the encoders stalled", zero
        stamps as encoder silence, a step as hundreds of missing samples).

        Raises:
            EstimatorError: more than ``max_gap_steps`` bad stamps in a row.
        """
        why, size = None, 0.0
        span = (self.max_gap + 1) * self.T_ns
        last = t0_ns + k * self.T_ns  # the last used tick's stamp
        d_stamp = stamp_ns - last
        if stamp_ns == 0:
            why = "encoder sample with a zero header stamp (unstamped)"
        elif d_stamp < -span:
            why, size = "encoder stamp behind the last one (a clock step back)", -d_stamp * 1e-9
        elif (
            d_stamp > span
            and sent_ns is not None
            and self.last_sent is not None
            and d_stamp > 4 * (sent_ns - self.last_sent)
        ):
            why = "encoder stamp ahead of its send time (a clock step or a corrupt stamp)"
            size = d_stamp * 1e-9
        if why is None:
            self.bad_run = 0
            self.last_sent = sent_ns
            return None
        skip(why)
        self.bad_run += 1
        if self.bad_run > self.max_gap:
            found = f"{self.bad_run} samples in a row after tick {k}"
            if size:
                found += f", the last {size:.4g} s from the last used stamp"
            raise EstimatorError(
                describe(
                    f"encoder stamps at t = {k * self.T:.3f} s",
                    "header stamps on the clock the node started on",
                    f"{why}: {found}",
                    "fix the driver's stamping clock (slew, do not step; stamp every "
                    "sample) and restart the node",
                )
            )
        return why
