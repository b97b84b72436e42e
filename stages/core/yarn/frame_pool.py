"""Frame samples paged in per yarn as a render's rays reach it: memory that follows the view (seed 000 §4-5).

A large cloth's frame samples (``frame_samples``: FRAME_COLS float64 per sample, some 8 M samples per 1,000
yarns) are most of what its lookups hold, and a close-up reaches a small share of its yarns. Tables derived
with ``accel.derive_lookup_accel(..., paged=True)`` keep none: each yarn's step, sample count, coarse knots,
chord grid, gates and fringe bits are there, its ``fs_at`` is -1. A lookup that needs yarn c's samples while
they are not resident sets ``fs_want[c]``, adds one to ``fs_miss`` and goes on as if c were not there
(``lookup.lookup_point``).

``FramePool(cv, tab)`` owns such tables' resident samples. A volpath lookup that missed answers
``stages.render.media.medium.PAGED_OUT``: tracking takes it as empty (so the ray's later lookups ask for their
yarns in the same round) and the path ends after that ray. The tile loop (``stages.render.tiles.render_tiles``,
``pager=``) renders in rounds, each thread with a miss counter of its own (``with_miss``), marking the pixels
whose lookups missed; those take all their samples again once ``page_in`` has made the wanted yarns resident.
A pixel depends only on its own random numbers, and its sums are kept only from a round in which none of its
lookups missed, so the picture is the one the fully resident tables give, byte for byte, whatever the rounds,
threads or order: each yarn's samples are made by the same kernel at the same step (``fs_step``) as a
resident derive makes them.

Memory: the resident samples live in one pair of arrays reserved at the size every yarn would take; memory
never written is never held (the operating system maps pages on first write), so the process holds the
samples of the yarns paged in, in the order they were asked for. A yarn once in stays in: the pool does not
evict (a view's yarns are paged in once; a render of the whole cloth ends with every yarn resident, as an
unpaged derive holds them from the start).

``resident(cv, tab, yarns)``: tables with the samples of ``yarns`` only, for the walks that visit every yarn
once (the majorant grid, ``stages.render.media.procedural_medium``), chunk by chunk.
"""
import time

import numpy as np

from .frame_samples import FRAME_COLS, sample_all


def is_paged(tab) -> bool:
    """Whether these derived tables hold fewer frame samples than their yarns have (some not resident)."""
    return bool(len(tab.fs_n) and np.any(np.asarray(tab.fs_at) < 0))


def resident(cv, tab, yarns):
    """``tab`` with the frame samples of ``yarns`` (ascending yarn indices) resident and no other's: fresh
    fs_at / fs_s / fs_frame arrays, ``tab``'s own left as they are."""
    yarns = np.asarray(yarns, np.int64)
    off, fs_s, fs_fr, _ = sample_all(cv, tab.fs_step, tab.yarn_extent, yarns, errors=False)
    _check_counts(tab, yarns, off)
    fs_at = np.full(len(tab.fs_n), -1, np.int64)
    fs_at[yarns] = off[:-1]
    return tab._replace(fs_at=fs_at, fs_s=fs_s, fs_frame=fs_fr)


def _check_counts(tab, yarns, off):
    if not np.array_equal(np.diff(off), np.asarray(tab.fs_n)[yarns]):
        raise RuntimeError("frame samples made again differ in number from the derived tables' (fs_n)")


def with_array(obj, old, new):
    """``obj`` (an integrator: namedtuples and tuples nesting arrays) with every reference to the array
    ``old`` replaced by ``new``; what does not hold ``old`` is returned as it is."""
    if obj is old:
        return new
    if isinstance(obj, tuple):
        items = [with_array(v, old, new) for v in obj]
        if all(a is b for a, b in zip(items, obj)):
            return obj
        return type(obj)(*items) if hasattr(obj, "_fields") else tuple(items)
    return obj


class FramePool:
    """The resident frame samples of paged tables (module doc). ``tables``: the tables to render with (the
    same arrays throughout: ``page_in`` writes into them in place). Counters: ``rounds`` (page_in calls),
    ``yarns_in`` and ``top`` (yarns and samples resident now), ``pixels_again`` (pixels rendered again)."""

    def __init__(self, cv, tab):
        self.cv = cv
        total = int(np.sum(tab.fs_n))
        # reserved, not written: the pages of the yarns paged in are all the process holds (module doc)
        fs_s = np.empty(total)
        fs_fr = np.empty((total, FRAME_COLS))
        self.tables = tab._replace(fs_at=np.full(len(tab.fs_n), -1, np.int64), fs_s=fs_s, fs_frame=fs_fr,
                                   fs_want=np.zeros(len(tab.fs_n), np.uint8), fs_miss=np.zeros(1, np.int64))
        self.top = 0
        self.rounds = 0
        self.yarns_in = 0
        self.pixels_again = 0
        self.pilot_rounds = 0        # of rounds and pixels_again, those of a pilot pass (pipeline.renderers.film)
        self.pilot_pixels_again = 0
        self.page_in_s = 0.0

    def with_miss(self, integ, miss):
        """``integ`` (holding ``tables``) whose lookups count their misses in ``miss`` ((1,) int64)."""
        return with_array(integ, self.tables.fs_miss, miss)

    def page_in(self) -> int:
        """Make every wanted yarn (``fs_want``) resident and clear the wants; the number paged in. A round
        that wants nothing new cannot make progress: RuntimeError."""
        tab = self.tables
        want = np.flatnonzero(np.asarray(tab.fs_want) != 0)
        tab.fs_want[:] = 0
        want = want[tab.fs_at[want] < 0]
        if not len(want):
            raise RuntimeError("frame pool: tiles missed, but no yarn was wanted")
        t0 = time.perf_counter()
        off = sample_all(self.cv, tab.fs_step, tab.yarn_extent, want, errors=False,
                         into=(tab.fs_s, tab.fs_frame, self.top))[0]   # made in place: no second copy
        _check_counts(tab, want, off)
        tab.fs_at[want] = off[:-1]
        self.top = int(off[-1])
        self.rounds += 1
        self.yarns_in += len(want)
        self.page_in_s += time.perf_counter() - t0
        return len(want)

    def info(self) -> dict:
        """What the pool did, for the render's record."""
        return {"frame_pool_yarns": int(self.yarns_in), "frame_pool_of_yarns": int(len(self.tables.fs_n)),
                "frame_pool_samples": int(self.top), "frame_pool_of_samples": int(np.sum(self.tables.fs_n)),
                "frame_pool_bytes": int(self.top * 8 * (FRAME_COLS + 1)), "frame_pool_rounds": int(self.rounds),
                "frame_pool_pixels_again": int(self.pixels_again), "frame_pool_pilot_rounds": int(self.pilot_rounds),
                "frame_pool_pilot_pixels_again": int(self.pilot_pixels_again), "frame_pool_page_in_s": self.page_in_s}
