"""The ingest stage: yarn-curve processing (``spline_process``: tangents, arc length, frames, the
per-yarn bound delta, the segment grid) and curve generators from weave drafts (``weave``) and knit
patterns (``knit``). Woven centrelines from an interlacement (also used by the tile stage) are in
``stages.core.curves.woven``; the knit loop model is in ``stages.core.curves.knit`` (``knit`` re-exports it)."""
