"""A fleet for tests and demos (`ddct-fleet generate`): N units, each with its own baseline
(detuned by the truth generator's seed) and one effect that evolves over its life, K logs per
unit written as MF4 by `ddct gap truth --mf4` — the gap issue's independent truth generator
(its own simulator and functional forms, never the diagnosis's code), so the truths stay outside
the diagnosis.

Effects over operating hours h (a unit's log k is at h = hours_per_log·(k + 1) + the unit's
offset):

- wear: the kiss point shifts with accumulated friction energy (class kiss_point_energy),
  magnitude 0.04 mm + 0.0007 mm/h;
- fade: the friction coefficient falls with temperature more and more (friction_temperature),
  magnitude −(0.02 + 0.0004/h·h);
- drift: the torque sensor's reading error grows (sensor_torque), 0.6 N·m + 0.03 N·m/h.

Layout: DIR/<unit>/<k>/{train.mf4, validate.mf4, truth.json}, DIR/manifest.csv (unit, log,
train, operating_hours: the per-unit-and-day pairing of docs/fleet.md) and DIR/truth.csv (the
truth of every log, for the report: the magnitude as the truth generator states it, and the
effect's term as a curve over its variable, from which the report reads the truth by the
diagnosis's definition of each finding's magnitude).
"""

from __future__ import annotations

import csv
import json
import random
import subprocess
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

# Start of the fleet's first log (2026-01-01 00:00 UTC) and the spacing of a unit's days.
EPOCH_S = 1_767_225_600
DAY_S = 86_400


@dataclass(frozen=True)
class Evolution:
    name: str
    klass: str
    family: str
    base: float
    per_hour: float


EVOLUTIONS = (
    Evolution("wear", "kiss_point_energy", "saturating", 0.04, 0.0007),
    Evolution("fade", "friction_temperature", "power", -0.02, -0.0004),
    Evolution("drift", "sensor_torque", "piecewise_linear", 0.6, 0.03),
)


@dataclass(frozen=True)
class LogSpec:
    unit: str
    index: int
    hours: float
    evolution: Evolution
    magnitude: float
    seed: int
    start_s: int


def plan(units: int, logs: int, hours_per_log: float, seed: int) -> list[LogSpec]:
    """Every log of the fleet: its unit, operating hours, effect and magnitude."""
    rng = random.Random(seed)
    specs = []
    for u in range(units):
        evo = EVOLUTIONS[u % len(EVOLUTIONS)]
        offset = rng.uniform(0.0, hours_per_log)
        unit_seed = seed * 10_000 + u
        for k in range(logs):
            h = round(hours_per_log * (k + 1) + offset, 3)
            specs.append(LogSpec(f"unit-{u:03d}", k, h, evo, evo.base + evo.per_hour * h, unit_seed,
                                 EPOCH_S + u * 3600 + k * DAY_S))
    return specs


def _generate_one(ddct: str, out: Path, s: LogSpec) -> dict:
    d = out / s.unit / f"{s.index:03d}"
    d.mkdir(parents=True, exist_ok=True)
    cmd = [ddct, "gap", "truth", "--class", s.evolution.klass, "--family", s.evolution.family,
           "--magnitude", repr(s.magnitude), "--detune", "0.05", "--seed", str(s.seed), "--out", str(d),
           "--mf4", "--start-time", str(s.start_s)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    for csv_file in d.glob("*.csv"):  # the MF4 logs are the fleet's records
        csv_file.unlink()
    truth = json.loads((d / "truth.json").read_text())
    curve = next((c for c in truth.get("curves", []) if c["class"] == s.evolution.klass), None)
    return {
        "unit": s.unit, "log": str((d / "validate.mf4").relative_to(out)),
        "train": str((d / "train.mf4").relative_to(out)), "operating_hours": s.hours,
        "evolution": s.evolution.name, "class": s.evolution.klass, "magnitude": truth["magnitude"],
        "magnitude_unit": truth["unit"], "effect_size": truth["effect_size"],
        # The effect's term over its variable (truth::curve): the truth by the diagnosis's
        # definition of a magnitude is read off it (report.truth_by_basis).
        "curve": json.dumps(curve["points"]) if curve else "",
    }


def generate(ddct: str, out: Path, units: int, logs: int, hours_per_log: float = 50.0, seed: int = 1,
             jobs: int = 2) -> list[dict]:
    """Writes the fleet into `out`; the truth rows."""
    out.mkdir(parents=True, exist_ok=True)
    specs = plan(units, logs, hours_per_log, seed)
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        rows = list(pool.map(lambda s: _generate_one(ddct, out, s), specs))
    with open(out / "manifest.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["unit", "log", "train", "operating_hours"])
        w.writeheader()
        for r in rows:
            w.writerow({k: r[k] for k in ("unit", "log", "train", "operating_hours")})
    with open(out / "truth.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    return rows
