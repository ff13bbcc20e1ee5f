"""The fleet report (`ddct-fleet report`): one self-contained HTML page (no script, no external
reference) from a findings dataset — the class counts across the fleet, the units that stand
out, and per unit a timeline of the fitted magnitude of its main class with the 95 % interval
against operating hours (the true magnitude overlaid when the fleet's truth.csv is given), every
point naming the log behind it. With the truth, the share of points whose interval holds the
true magnitude, over the points where the effect is above 3× the noise, is reported.
"""

from __future__ import annotations

import bisect
import csv
import html
import json
import math
from collections import Counter, defaultdict
from pathlib import Path

import pyarrow.dataset as ds

# Points where the effect is at least this many times the noise count for the recovery figure.
STRONG_EFFECT = 3.0
# A unit stands out when its latest magnitude is this many robust deviations from its class.
OUTLIER_Z = 3.0


def load_findings(path) -> list[dict]:
    """Every row of a findings dataset (a directory or a URL fsspec opens)."""
    if "://" in str(path):
        import fsspec

        fs, p = fsspec.core.url_to_fs(str(path))
        return ds.dataset(p, format="parquet", filesystem=fs).to_table().to_pylist()
    return ds.dataset(Path(path), format="parquet").to_table().to_pylist()


def load_truth(path: Path | None) -> dict[str, dict]:
    """truth.csv rows by the absolute path of their validation log."""
    if path is None:
        return {}
    base = Path(path).resolve().parent
    with open(path, newline="") as f:
        return {str((base / r["log"]).resolve()): r for r in csv.DictReader(f)}


def main_class(rows: list[dict]) -> str | None:
    c = Counter(r["class"] for r in rows if r["kind"] in ("class", "sensor") and r["class"])
    return c.most_common(1)[0][0] if c else None


# Units that mean the same quantity: a relative change is dimensionless.
_SAME_UNIT = {"1": "1", "relative": "1"}


def comparable(fit_unit: str | None, truth_unit: str | None) -> bool:
    """Whether a fitted magnitude and a true one are on the same scale (both units known and
    alike). Used only where the truth has no curve to read by the finding's basis."""
    if not fit_unit or not truth_unit:
        return False
    return _SAME_UNIT.get(fit_unit, fit_unit) == _SAME_UNIT.get(truth_unit, truth_unit)


def _interp(points: list[list[float]], x: float) -> float:
    xs = [p[0] for p in points]
    if x <= xs[0]:
        return points[0][1]
    if x >= xs[-1]:
        return points[-1][1]
    i = bisect.bisect_right(xs, x)
    (x0, y0), (x1, y1) = points[i - 1], points[i]
    return y0 + (y1 - y0) * (x - x0) / (x1 - x0)


def truth_by_basis(points: list[list[float]], basis: str | None, lo: float | None, hi: float | None) -> float | None:
    """The true magnitude by a finding's definition of it, read off the truth's curve (the
    effect's term over its variable, written by the truth generator from its own forms):
    ``change`` — the term's change from lo to hi; ``ratio`` — a multiplier 1 + y's relative
    change from lo to hi, (1 + y(hi))/(1 + y(lo)) − 1; ``largest`` — its value of largest size over
    [lo, hi] with its sign; ``at`` — its value at lo. ``None`` when the basis needs no curve or
    the range is unknown."""
    if not points or lo is None or hi is None:
        return None
    if basis == "change":
        return _interp(points, hi) - _interp(points, lo)
    if basis == "ratio":
        return (1.0 + _interp(points, hi)) / (1.0 + _interp(points, lo)) - 1.0
    if basis == "at":
        return _interp(points, lo)
    if basis == "largest":
        inside = [y for x, y in points if lo < x < hi] + [_interp(points, lo), _interp(points, hi)]
        return max(inside, key=abs)
    return None


def ambiguous_with(row: dict) -> list[str]:
    """The classes a finding's row is ambiguous with (they explain the validation records as
    well as it does), from its detail."""
    try:
        return list(json.loads(row.get("detail") or "{}").get("ambiguous_with") or [])
    except (ValueError, AttributeError):
        return []


def unit_points(rows: list[dict], klass: str, truth: dict[str, dict]) -> list[dict]:
    """Per log of a unit: hours, fitted magnitude and interval of `klass` (None when the log's
    diagnosis did not find it), the truth where known — by the finding's definition of the
    magnitude where the truth has a curve, else as the truth generator states it.

    A log whose diagnosis names another class first with `klass` in its ambiguity set (two
    classes the records cannot tell apart, e.g. a fade of μ and of the spring load over
    temperature, which multiply the torque (13) alike) gives that finding's magnitude for
    `klass`, marked with the class named (``named``); a finding of `klass` itself comes first."""
    by_log: dict[str, dict] = {}
    for r in rows:
        p = by_log.setdefault(r["log"], {"log": r["log"], "hours": r["operating_hours"], "start": r["start_time"],
                                         "fit": None, "lo": None, "hi": None, "error": None, "fit_unit": None,
                                         "basis": None, "from": None, "to": None, "named": None})
        if r["kind"] == "error":
            p["error"] = r["error"]
        if r["kind"] not in ("class", "sensor"):
            continue
        exact = r["class"] == klass
        if exact or (p["fit"] is None and klass in ambiguous_with(r)):
            p.update(fit=r["magnitude"], lo=r["magnitude_lo"], hi=r["magnitude_hi"], fit_unit=r["magnitude_unit"],
                     basis=r.get("magnitude_basis"), named=r["class"],
                     **{"from": r.get("magnitude_from"), "to": r.get("magnitude_to")})
    points = list(by_log.values())
    for p in points:
        t = truth.get(p["log"])
        p["class"] = klass
        p["effect_size"] = float(t["effect_size"]) if t else None
        p["truth"] = p["truth_unit"] = None
        if not t or t["class"] != klass:
            continue
        curve = json.loads(t["curve"]) if t.get("curve") else None
        by_basis = truth_by_basis(curve, p["basis"], p["from"], p["to"]) if curve else None
        if by_basis is not None:
            p["truth"], p["truth_unit"] = by_basis, p["fit_unit"]
        elif p["fit"] is None or p["basis"] in (None, "parameter"):
            p["truth"], p["truth_unit"] = float(t["magnitude"]), t["magnitude_unit"]
    return sorted(points, key=lambda p: (p["hours"] is None, p["hours"] or 0.0, p["log"]))


def recovery(points_by_unit: dict[str, list[dict]]) -> tuple[int, int, int, dict[str, list[int]]]:
    """(points whose interval holds the truth, strong points, strong points whose fitted and
    true magnitudes are on different scales, [hit, strong] per class), over points with a known
    truth whose effect is at least STRONG_EFFECT × the noise. A point whose class was not found
    counts as missed; one on another scale counts apart, neither hit nor missed."""
    hit = n = other_scale = 0
    by_class: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    for pts in points_by_unit.values():
        for p in pts:
            if (p["effect_size"] or 0.0) < STRONG_EFFECT:
                continue
            if p["fit"] is not None and (p["truth"] is None or not comparable(p["fit_unit"], p["truth_unit"])):
                other_scale += 1
                continue
            if p["truth"] is None:
                continue
            n += 1
            by_class[p["class"]][1] += 1
            if p["lo"] is not None and p["lo"] <= p["truth"] <= p["hi"]:
                hit += 1
                by_class[p["class"]][0] += 1
    return hit, n, other_scale, dict(by_class)


def outliers(latest: dict[str, tuple[str, float]]) -> list[tuple[str, str, float]]:
    """Units whose latest magnitude lies more than OUTLIER_Z robust deviations (MAD) from the
    median of the units with the same main class."""
    by_class: dict[str, list[tuple[str, float]]] = defaultdict(list)
    for unit, (klass, m) in latest.items():
        by_class[klass].append((unit, m))
    out = []
    for klass, ms in by_class.items():
        if len(ms) < 3:
            continue
        vals = sorted(m for _, m in ms)
        med = vals[len(vals) // 2]
        mad = sorted(abs(v - med) for v in vals)[len(vals) // 2] * 1.4826
        for unit, m in ms:
            z = abs(m - med) / mad if mad > 0 else 0.0
            if z > OUTLIER_Z:
                out.append((unit, klass, z))
    return out


def svg_timeline(points: list[dict], unit_label: str) -> str:
    """An SVG of fitted magnitude (dots with interval bars) and truth (rings) over hours."""
    w, h, m = 640, 220, 48
    xs = [p["hours"] for p in points if p["hours"] is not None]
    ys = [v for p in points for v in (p["fit"], p["lo"], p["hi"], p["truth"]) if v is not None and math.isfinite(v)]
    if not xs or not ys:
        return "<p>no magnitudes to draw</p>"
    x0, x1 = min(xs), max(xs)
    y0, y1 = min(ys + [0.0]), max(ys + [0.0])
    x1 = x1 if x1 > x0 else x0 + 1
    pad = (y1 - y0) * 0.08 or 1.0
    y0, y1 = y0 - pad, y1 + pad
    sx = lambda x: m + (x - x0) / (x1 - x0) * (w - 2 * m)  # noqa: E731
    sy = lambda y: h - m - (y - y0) / (y1 - y0) * (h - 2 * m)  # noqa: E731
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" role="img" '
             f'aria-label="{html.escape(unit_label)}">',
             f'<rect x="0" y="0" width="{w}" height="{h}" fill="white"/>',
             f'<line x1="{m}" y1="{h - m}" x2="{w - m}" y2="{h - m}" stroke="#444"/>',
             f'<line x1="{m}" y1="{m}" x2="{m}" y2="{h - m}" stroke="#444"/>',
             f'<text x="{w / 2}" y="{h - 10}" text-anchor="middle" font-size="12">operating hours</text>',
             f'<text x="{m - 6}" y="{sy(y1):.1f}" text-anchor="end" font-size="11">{y1:.3g}</text>',
             f'<text x="{m - 6}" y="{sy(y0):.1f}" text-anchor="end" font-size="11">{y0:.3g}</text>',
             f'<text x="{sx(x0):.1f}" y="{h - m + 14}" text-anchor="middle" font-size="11">{x0:.0f}</text>',
             f'<text x="{sx(x1):.1f}" y="{h - m + 14}" text-anchor="middle" font-size="11">{x1:.0f}</text>']
    truth_line = [(sx(p["hours"]), sy(p["truth"])) for p in points if p["truth"] is not None and p["hours"] is not None]
    if len(truth_line) > 1:
        parts.append('<polyline fill="none" stroke="#c33" stroke-dasharray="4 3" points="'
                     + " ".join(f"{x:.1f},{y:.1f}" for x, y in truth_line) + '"/>')
    for p in points:
        if p["hours"] is None:
            continue
        x = sx(p["hours"])
        tip = html.escape(f"{p['log']}: {p['hours']} h, fitted {p['fit']} [{p['lo']}, {p['hi']}], truth {p['truth']}")
        if p["truth"] is not None:
            parts.append(f'<circle cx="{x:.1f}" cy="{sy(p["truth"]):.1f}" r="5" fill="none" stroke="#c33">'
                         f'<title>{tip}</title></circle>')
        if p["fit"] is not None:
            if p["lo"] is not None and p["hi"] is not None:
                parts.append(f'<line x1="{x:.1f}" y1="{sy(p["lo"]):.1f}" x2="{x:.1f}" y2="{sy(p["hi"]):.1f}" '
                             f'stroke="#236" stroke-width="2"/>')
            parts.append(f'<circle cx="{x:.1f}" cy="{sy(p["fit"]):.1f}" r="3.5" fill="#236"><title>{tip}</title></circle>')
        elif p["error"]:
            parts.append(f'<text x="{x:.1f}" y="{m + 10}" font-size="14" fill="#b00" text-anchor="middle">×'
                         f'<title>{tip}: {html.escape(p["error"][:200])}</title></text>')
    parts.append("</svg>")
    return "".join(parts)


def render(findings_dir: Path, truth_csv: Path | None = None) -> tuple[str, dict]:
    """The page and its figures (class counts, outliers, recovery)."""
    rows = load_findings(findings_dir)
    truth = load_truth(truth_csv)
    by_unit: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        by_unit[r["unit"] or "(no unit)"].append(r)
    logs = {r["log"] for r in rows}
    errors = {r["log"] for r in rows if r["kind"] == "error"}
    counts = Counter((r["kind"], r["class"] or r["subsystem"] or "") for r in rows if r["kind"] != "error")
    points_by_unit, latest = {}, {}
    for unit, urows in sorted(by_unit.items()):
        # The class the unit's truth names (the effect the report must recover: a unit whose
        # effect was never found still gets its timeline, the truth and the missing fits), else
        # the class its diagnoses name most.
        klass = next((truth[r["log"]]["class"] for r in urows if r["log"] in truth), None) or main_class(urows)
        if klass is None:
            continue
        pts = unit_points(urows, klass, truth)
        points_by_unit[unit] = pts
        fitted = [p for p in pts if p["fit"] is not None]
        if fitted:
            latest[unit] = (klass, fitted[-1]["fit"])
    hit, strong, other_scale, by_class = recovery(points_by_unit)
    odd = outliers(latest)
    figures = {"logs": len(logs), "units": len(by_unit), "error_logs": len(errors),
               "recovered": hit, "strong_points": strong, "other_scale_points": other_scale,
               "recovered_by_class": by_class,
               "outliers": [u for u, _, _ in odd]}
    e = html.escape
    out = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>ddct fleet report</title>",
           "<style>body{font-family:sans-serif;margin:2em;max-width:72em}table{border-collapse:collapse}"
           "td,th{border:1px solid #ccc;padding:2px 8px;text-align:left}.err{color:#b00}</style></head><body>",
           "<h1>ddct fleet report</h1>",
           f"<p>{len(logs)} logs of {len(by_unit)} units, {len(rows)} findings, "
           f"<span class='err'>{len(errors)} logs without a diagnosis (error rows)</span>.</p>"]
    if truth:
        share = f"{100 * hit / strong:.0f} %" if strong else "n/a"
        out.append(f"<p>Recovery: the fitted interval holds the true magnitude at {hit} of {strong} points "
                   f"where the effect is above {STRONG_EFFECT:g}× the noise ({share}); {other_scale} more "
                   f"points are fitted on another scale than the truth's (units in the tables).</p>")
    out.append("<h2>Classes across the fleet</h2><table><tr><th>kind</th><th>class or subsystem</th><th>findings</th></tr>")
    for (kind, what), n in counts.most_common():
        out.append(f"<tr><td>{e(kind)}</td><td>{e(what)}</td><td>{n}</td></tr>")
    out.append("</table><h2>Units that stand out</h2><ul>")
    for unit, klass, z in odd:
        out.append(f"<li>{e(unit)}: latest {e(klass)} magnitude {z:.1f} robust deviations from the fleet</li>")
    for unit in sorted({r["unit"] for r in rows if r["kind"] == "error"}):
        out.append(f"<li class='err'>{e(unit or '')}: logs without a diagnosis</li>")
    out.append("</ul><h2>Units</h2>")
    for unit, pts in points_by_unit.items():
        klass = pts[0]["class"]
        out.append(f"<h3 id='{e(unit)}'>{e(unit)}: {e(klass or '')}</h3>")
        out.append(svg_timeline(pts, f"{unit} {klass}"))
        units = f"{pts[0]['fit_unit'] or next((p['fit_unit'] for p in pts if p['fit_unit']), '')}"
        truth_units = next((p["truth_unit"] for p in pts if p["truth_unit"]), "")
        out.append(f"<table><tr><th>hours</th><th>fitted ({e(units)})</th><th>95 % interval</th>"
                   f"<th>truth ({e(truth_units)})</th><th>log</th></tr>")
        for p in pts:
            ci = f"[{p['lo']:.4g}, {p['hi']:.4g}]" if p["lo"] is not None else ""
            fit = f"{p['fit']:.4g}" if p["fit"] is not None else (f"<span class='err'>{e((p['error'] or 'not found')[:120])}</span>")
            if p.get("named") and p["named"] != klass:
                fit += f" <small>(named {e(p['named'])}, ambiguous with {e(klass)})</small>"
            tr = f"{p['truth']:.4g}" if p["truth"] is not None else ""
            out.append(f"<tr><td>{p['hours']}</td><td>{fit}</td><td>{ci}</td><td>{tr}</td><td>{e(p['log'])}</td></tr>")
        out.append("</table>")
    out.append("</body></html>")
    return "\n".join(out), figures
