"""`ddct log plot`: a bench run's log (in-process bus) drawn with the lockstep simulation of its
scenario overlaid. Checked as a user would look at it: a well-formed SVG under 200 kB, a legend
entry per chosen signal for the bus and the simulation, the TCU states and gears as named lanes,
the fault code marked; bad signal names refused naming the signal. The values themselves are
checked against encoded frames in the unit tests (src/sim/logplot.rs)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

import ddct_testlib as lib

SCENARIO = lib.REPO / "config" / "scenarios" / "launch_shift_20s.toml"


def texts(svg) -> set[str]:
    return {"".join(e.itertext()).strip() for e in ET.parse(svg).getroot().iter() if e.tag.endswith("text")}


def with_engine_stop(tmp_path):
    """The bench scenario with ENG_Status stopped for 0.2 s at 12 s (the TCU's EngStatusTimeout,
    allowed by its limits): a fault code for the plot to mark."""
    text = SCENARIO.read_text().replace("[limits]\n", '[limits]\nfaults_allowed = ["EngStatusTimeout"]\n')
    text += '\n[[faults]]\nmessage = "ENG_Status"\nkind = "stop"\nfrom_s = 12.0\nto_s = 12.2\n'
    path = tmp_path / "launch_shift_stop.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def benches(ddct, tmp_path_factory) -> dict:
    """The two tests' bench runs (in-process bus, real time, little CPU), started together:
    {"stop": (scenario, folder, run) of the bench scenario with the engine stop, "launch_50": ...}."""
    d = tmp_path_factory.mktemp("log_plot")
    scenarios = {"stop": with_engine_stop(d), "launch_50": lib.REPO / "config" / "scenarios" / "launch_50.toml"}
    runs = lib.run_together({k: [ddct, "bench", "--iface", "sim", "--echo", "0", "--scenario", s, "--out", d / k]
                             for k, s in scenarios.items()}, timeout=300)
    return {k: (scenarios[k], d / k, runs[k]) for k in scenarios}


def test_log_plot_overlays_the_simulation(ddct, benches, tmp_path):
    scenario, out, r = benches["stop"]
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    svg = tmp_path / "overlay.svg"
    signals = ["EngSpeed", "DCT_Sensors.InShaft1Speed", "TCU_Status.TcuState", "GearActive"]
    args = [ddct, "log", "plot", out / "bench.log", "--sim", scenario, "--out", svg]
    for s in signals:
        args += ["-s", s]
    r = lib.run(args, check=False)
    assert r.returncode == 0, r.stderr
    assert f"wrote {svg}" in r.stdout
    size = svg.stat().st_size
    assert 5_000 < size < 200_000, size
    t = texts(svg)
    for name in ("ENG_Status.EngSpeed", "DCT_Sensors.InShaft1Speed", "TCU_Status.TcuState", "TCU_Status.GearActive"):
        assert f"{name} (bus)" in t and f"{name} (sim)" in t, (name, sorted(t)[:40])
    # Lanes named by the DBC's value tables; the engine stop's timeout marked.
    assert {"Init", "Launch", "Drive", "Upshift", "N", "G1", "G3"} <= t, sorted(t)
    assert "EngStatusTimeout" in t
    assert "Signals in rpm" in t


def test_log_plot_defaults_and_refusals(ddct, benches, tmp_path):
    _, out, r = benches["launch_50"]
    assert r.returncode in (0, 1), r.stderr[-2000:]
    r = lib.run([ddct, "log", "plot", out / "bench.log"], check=False)
    assert r.returncode == 0, r.stderr
    t = texts(out / "bench.svg")
    assert {"Signals in rpm", "Signals in Nm", "Signals in mm", "TCU_Status.TcuState"} <= t, sorted(t)
    r = lib.run([ddct, "log", "plot", out / "bench.log", "-s", "Crc"], check=False)
    assert r.returncode != 0 and "--signal Crc" in r.stderr and "several messages" in r.stderr, r.stderr
    r = lib.run([ddct, "log", "plot", out / "bench.log", "-s", "ENG_Status.Nope"], check=False)
    assert r.returncode != 0 and "unknown signal `ENG_Status.Nope`" in r.stderr, r.stderr
    empty = tmp_path / "empty.log"
    empty.write_text("")
    r = lib.run([ddct, "log", "plot", empty], check=False)
    assert r.returncode != 0 and "no frame in the log" in r.stderr, r.stderr
