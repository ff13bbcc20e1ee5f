"""Text for the progress lines of the long scripts (scripts/xcp_flood.py, scripts/diag_timing.py)."""


def duration(s: float) -> str:
    """`s` as "42 s", "3 min 05 s" or "1 h 02 min"."""
    s = max(0, round(s))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"
